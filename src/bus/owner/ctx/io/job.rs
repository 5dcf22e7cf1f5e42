//! The frames of a one-shot request: each waits for the line, lets the
//! setpoints waiting out first where the scheduler allows, and gives way
//! to an e-stop; a request that wants an answer is retried on silence.

use std::sync::LazyLock;
use std::time::{Duration, Instant};

use crate::bus::error::BusError;
use crate::bus::owner::confirm::describe;
use crate::bus::wire::Want;
use crate::logcap::Collapse;
use crate::protocol::{Command, Config, ConfigParam, Reply};

use super::super::Ctx;
use super::Silence;

/// How often an unanswered read of the same device is logged.
const UNANSWERED_LOG_WINDOW: Duration = Duration::from_secs(10);

/// Reads no attempt of which was answered, collapsed per bus and device.
static UNANSWERED: LazyLock<Collapse> = LazyLock::new(|| Collapse::new(UNANSWERED_LOG_WINDOW));

impl Ctx {
    /// A request/response transaction of a one-shot request, retried
    /// `attempts` times in all. `None` after the last timeout.
    pub(crate) fn try_transact(
        &mut self,
        cmd: Config,
        want: Want,
        attempts: u32,
    ) -> Result<Option<Reply>, BusError> {
        for attempt in 0..attempts.max(1) {
            if attempt > 0 {
                self.link.counters.retries += 1;
            }
            self.before_job_frame()?;
            if let Some(reply) = self.exchange(cmd, want, false)? {
                return Ok(Some(reply));
            }
        }
        Ok(None)
    }

    /// A firmware probe: one read whose silence is an answer (V2.0.1
    /// firmware does not know the index), so it counts as an unanswered
    /// probe, not as a timeout or a missed poll.
    pub(crate) fn probe(&mut self, cmd: Config, want: Want) -> Result<Option<Reply>, BusError> {
        self.link.counters.firmware_probes += 1;
        self.before_job_frame()?;
        self.exchange_as(cmd, want, false, Silence::Answer)
    }

    /// [`Self::try_transact`] with the configured retries; a timeout is an error.
    pub(crate) fn transact(&mut self, cmd: Config, want: Want) -> Result<Reply, BusError> {
        let attempts = 1 + self.cfg.timing.retries;
        self.try_transact(cmd, want, attempts)?.ok_or_else(|| {
            let error = self.timeout_error(want.dev_id, &cmd.param, attempts);
            self.log_unanswered(want.dev_id, &error);
            error
        })
    }

    /// The client sees the timeout; the bus's log says what the line showed
    /// meanwhile (garbage, replies taken in late). One line per bus and
    /// device per window, so a client looping reads of a silent device does
    /// not flood the log.
    fn log_unanswered(&self, dev_id: u8, error: &BusError) {
        let key = format!("{} {dev_id}", self.cfg.name);
        let Some(held) = UNANSWERED.admit(&key, Instant::now()) else {
            return;
        };
        let c = &self.link.counters;
        tracing::warn!(
            bus = %self.cfg.name,
            crc_errors = c.crc_errors,
            unsolicited = c.unsolicited,
            timeouts = c.timeouts,
            "{error}{}",
            UNANSWERED.held_note(held)
        );
    }

    pub(crate) fn timeout_error(&self, dev_id: u8, param: &ConfigParam, attempts: u32) -> BusError {
        let timeout = self.sched.clock().reply_timeout(Instant::now());
        BusError::Timeout {
            dev_id,
            what: describe(param),
            attempts,
            timeout_us: timeout.as_micros() as u64,
        }
    }

    /// Writes frames of a one-shot request that expect no reply.
    pub(crate) fn job_send(&mut self, cmds: &[Command]) -> Result<(), BusError> {
        self.before_job_frame()?;
        self.send(cmds)?;
        Ok(())
    }

    /// Before each frame of a one-shot request: wait for the line, let
    /// waiting setpoints out if the scheduler allows, and give way to an
    /// e-stop.
    fn before_job_frame(&mut self) -> Result<(), BusError> {
        loop {
            self.wait_confirmed()?;
            self.wait_until(self.sched.write_at(Instant::now()))?;
            let generation = self.estop_generation();
            let now = Instant::now();
            let interleave = self
                .sched
                .interleave(now, &self.shared.setpoints, generation);
            self.after_decision();
            match interleave {
                Some(frame) => self.send_planned(frame)?,
                None => break,
            }
        }
        self.housekeeping(Instant::now());
        if self.sched.job_frame(self.estop_generation()).is_err() {
            return Err(BusError::Preempted);
        }
        if !self.link.is_up() {
            return Err(self.down_error());
        }
        Ok(())
    }

    /// Until a frame may go out as the scheduler lets an e-stop out: the
    /// write before seen taken (or its count given up on) and the line
    /// free of the replies it asked for. For a write outside the owner's
    /// turns (the shutdown's disable), which would otherwise go at once.
    pub(crate) fn wait_for_line(&mut self) -> Result<(), BusError> {
        self.wait_confirmed()?;
        self.wait_until(self.sched.write_at(Instant::now()))
    }

    /// Until the write before is seen taken (or its count given up on,
    /// within [`crate::bus::usb::confirm::MAX_UNTAKEN`]): a request's frames,
    /// and the setpoints let out between them, go one after another without
    /// the owner's turn, whose look at the port's count this stands in for.
    fn wait_confirmed(&mut self) -> Result<(), BusError> {
        loop {
            self.look_at_count();
            if !self.sched.awaiting_confirmation() {
                return Ok(());
            }
            self.wait_until(self.sched.write_at(Instant::now()))?;
        }
    }
}
