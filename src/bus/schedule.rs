//! The owner's wire primitives: waiting for the line, putting setpoints on
//! it (coalesced, acknowledged), telemetry polls, and the request/response
//! transactions one-shot requests are made of.
//!
//! Every frame is handed to the port when the [`super::wire::WireClock`]
//! says the line is about to free; after a request that expects a reply,
//! nothing is written until the reply arrives or its deadline passes.

use std::time::{Duration, Instant};

use crate::protocol::{Command, Config, ConfigParam, Reply, ReplyBody};

use super::coalesce::{self, Pending, Planned};
use super::error::BusError;
use super::handle::WireAck;
use super::link::Want;
use super::owner::Owner;

/// Setpoint frames that may go out between two frames of a one-shot
/// request, so a long scan does not freeze the joints.
const MAX_INTERLEAVED: u32 = 2;
/// How long before a reply is due the next control frame is planned:
/// ample for planning, short enough that the setpoints it samples are fresh.
const PREPARE_LEAD: Duration = Duration::from_micros(100);
/// How often a reply wait past its modelled time looks for an e-stop.
const LATE_WAIT_SLICE: Duration = Duration::from_millis(1);
/// How long before a reply is due the owner stops sleeping.
const SPIN_BEFORE_DUE: Duration = Duration::from_micros(10);

impl Owner {
    /// Listens until `at`; replies nobody waited for are taken in.
    pub(super) fn wait_until(&mut self, at: Instant) -> Result<(), BusError> {
        let waited = self.link.wait(None, at);
        self.absorb_inbox();
        waited.map(|_| ()).map_err(|e| self.lost(e))
    }

    /// Unsolicited replies: power-up announcements, late replies.
    pub(super) fn absorb_inbox(&mut self) {
        let inbox = std::mem::take(&mut self.link.inbox);
        for (reply, at) in &inbox {
            self.link.counters.unsolicited += 1;
            let late = self
                .overdue
                .take_if(|(w, _)| w.dev_id == reply.dev_id && w.index == reply.index);
            if let Some((_, due)) = late {
                self.link.clock.observe_reply(due, *at);
            }
            let effect = self
                .reg
                .on_reply(reply, *at, late.is_some(), &mut self.events);
            if effect.rebooted {
                // A rebooted device is disabled and forgot its target:
                // whatever was waiting for it is stale.
                self.shared.setpoints.clear(Some(&[reply.dev_id]));
                self.pending.remove(&reply.dev_id);
                self.prepared = None;
            }
            self.resend_if_aligned(reply.dev_id, effect);
        }
        self.link.inbox = inbox;
        self.link.inbox.clear();
    }

    /// Takes what changed in the setpoint store into `pending`.
    pub(super) fn collect_setpoints(&mut self) {
        for (id, setpoint) in self.shared.setpoints.changed_since(self.seen_seq) {
            self.seen_seq = self.seen_seq.max(setpoint.seq);
            let since = self.pending.get(&id).map_or(setpoint.accepted, |p| p.since);
            self.pending.insert(id, Pending { setpoint, since });
        }
    }

    /// Writes the frame carrying the oldest pending setpoint; false when
    /// nothing needs a frame. A frame prepared while the last reply was on
    /// the wire is used if no setpoint came in since.
    pub(super) fn send_control(&mut self) -> Result<bool, BusError> {
        let prepared = self.prepared.take();
        let planned = match prepared {
            Some((frame, seq)) if seq == self.shared.setpoints.latest_seq() => Some(frame),
            _ => {
                self.collect_setpoints();
                self.plan_control()
            }
        };
        match planned {
            Some(frame) => self.send_planned(frame).map(|()| true),
            None => Ok(false),
        }
    }

    /// The frame carrying the oldest pending setpoint; drops what needs none.
    fn plan_control(&mut self) -> Option<Planned> {
        if self.pending.is_empty() {
            return None;
        }
        let plan = coalesce::plan(&self.pending, |id| self.reg.slot_info(id));
        for (id, sp) in &plan.settled {
            self.settle(*id, sp.seq);
        }
        for id in &plan.unknown {
            self.pending.remove(id);
            self.link.counters.setpoints_dropped += 1;
        }
        let first = plan.frames.into_iter().next();
        if first.is_none() {
            self.publish_ack(Instant::now());
        }
        first
    }

    /// While a reply is on the wire: sample the setpoints and plan the frame
    /// that follows it, so the line idles no longer than needed after the
    /// reply (planning takes µs a cold cache makes tens of).
    fn prepare_control(&mut self, at: Instant) {
        self.collect_setpoints();
        let latest = self.shared.setpoints.latest_seq();
        self.prepared = if !self.pending.is_empty() && self.budget.allows(at) {
            self.plan_control().map(|frame| (frame, latest))
        } else {
            None
        };
    }

    fn send_planned(&mut self, frame: Planned) -> Result<(), BusError> {
        let end = self.link.send(&[frame.command]).map_err(|e| self.lost(e))?;
        self.budget.spend(self.link.clock.frame_time());
        for (id, sp) in frame.carries {
            self.reg.record_sent(id, sp.setpoint, end);
            self.settle(id, sp.seq);
            self.stats
                .setpoint_age(end.saturating_duration_since(sp.accepted));
            self.link.counters.setpoints_sent += 1;
        }
        self.publish_ack(end);
        Ok(())
    }

    /// Drops `id` from pending unless a newer setpoint replaced it meanwhile.
    fn settle(&mut self, id: u8, seq: u64) {
        if self.pending.get(&id).is_some_and(|p| p.setpoint.seq <= seq) {
            self.pending.remove(&id);
        }
    }

    /// Publishes the highest sequence number all of whose joints are on the wire.
    fn publish_ack(&mut self, at: Instant) {
        let oldest_pending = self.pending.values().map(|p| p.setpoint.seq).min();
        let seq = oldest_pending.map_or(self.seen_seq, |s| s.saturating_sub(1));
        if seq > self.acked_seq {
            self.acked_seq = seq;
            self.shared
                .wire_acks
                .send_replace(WireAck { seq, at: Some(at) });
        }
    }

    /// One telemetry poll; false when there is nobody to poll.
    pub(super) fn poll_once(&mut self) -> Result<bool, BusError> {
        let now = Instant::now();
        let timeout = self.link.clock.reply_deadline(now) - now;
        let Some(poll) = self.planner.next(self.reg.poll_states(), now, timeout) else {
            return Ok(false);
        };
        self.link.counters.polls += 1;
        let want = Want {
            dev_id: poll.dev_id,
            index: poll.block.index(),
        };
        self.exchange(Config::read(poll.dev_id, poll.block), want, true)?;
        Ok(true)
    }

    /// Writes one config/read frame and waits for the reply it asks for;
    /// with `prepare`, plans the next control frame meanwhile. `None` when
    /// the reply did not come in time (counted as a missed poll).
    fn exchange(
        &mut self,
        cmd: Config,
        want: Want,
        prepare: bool,
    ) -> Result<Option<Reply>, BusError> {
        let end = self
            .link
            .send(&[Command::Config(cmd)])
            .map_err(|e| self.lost(e))?;
        let due = self.link.clock.reply_due(end);
        let mut got = Ok(None);
        if prepare {
            let prepare_at = due.checked_sub(PREPARE_LEAD).unwrap_or(due);
            got = self.link.wait(Some(want), prepare_at);
            if matches!(got, Ok(None)) {
                self.prepare_control(due);
            }
        }
        if matches!(got, Ok(None)) {
            got = self.wait_reply(want, due, self.link.clock.reply_deadline(end));
        }
        self.absorb_inbox();
        let got = got.map_err(|e| self.lost(e))?;
        Ok(self.settle_exchange(got, want, due))
    }

    /// Waits for `want` until `deadline`. Past a frame after the modelled
    /// reply the wait goes in short slices: a late or missing reply must not
    /// hold an e-stop back, nor the snapshot.
    fn wait_reply(
        &mut self,
        want: Want,
        due: Instant,
        deadline: Instant,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        let grace = due + self.link.clock.frame_time();
        let mut got = self.spin_for_reply(want, due);
        if matches!(got, Ok(None)) {
            got = self.link.wait(Some(want), grace.min(deadline));
        }
        while matches!(got, Ok(None)) && !self.estop_pending() {
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            self.housekeeping(now);
            got = self
                .link
                .wait(Some(want), deadline.min(now + LATE_WAIT_SLICE));
        }
        got
    }

    /// Blocks until shortly before the reply is due, then looks at the port
    /// without sleeping for `reply_spin_us`: a thread woken from sleep (on a
    /// VM, a halted virtual CPU woken too) reacts tens of µs later, and every
    /// poll's reply is followed by such a gap on the line.
    fn spin_for_reply(
        &mut self,
        want: Want,
        due: Instant,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        let spin = Duration::from_micros(self.cfg.timing.reply_spin_us);
        if spin.is_zero() {
            return Ok(None);
        }
        let spin_from = due.checked_sub(SPIN_BEFORE_DUE).unwrap_or(due);
        let mut got = self.link.wait(Some(want), spin_from);
        while matches!(got, Ok(None)) && Instant::now() < due + spin {
            std::hint::spin_loop();
            got = self.link.poll_now(Some(want));
        }
        got
    }

    /// Takes in the reply of an exchange, or counts it missing.
    fn settle_exchange(
        &mut self,
        got: Option<(Reply, Instant)>,
        want: Want,
        due: Instant,
    ) -> Option<Reply> {
        let Some((reply, at)) = got else {
            self.overdue = Some((want, due));
            self.link.counters.timeouts += 1;
            self.link.clock.line_free(Instant::now());
            self.reg.on_missed(want.dev_id, &mut self.events);
            return None;
        };
        self.link.clock.observe_reply(due, at);
        // A RES from a new id (SET_ID) is not a device yet: the request
        // renames the old entry itself.
        let feeds =
            self.reg.get(reply.dev_id).is_some() || matches!(reply.body(), ReplyBody::Info01(_));
        if feeds {
            let effect = self.reg.on_reply(&reply, at, true, &mut self.events);
            self.resend_if_aligned(reply.dev_id, effect);
        }
        Some(reply)
    }

    /// A joint that just finished aligning gets its latest target again,
    /// through the store like any client write (a newer write wins).
    fn resend_if_aligned(&mut self, id: u8, effect: super::registry::ReplyEffect) {
        if !effect.now_running {
            return;
        }
        if let Some(latest) = self.shared.setpoints.get(id) {
            // What went out during align does not count as on the device.
            self.reg.forget_target(id);
            self.shared.setpoints.set(&[(id, latest.setpoint)]);
        }
    }

    /// A request/response transaction of a one-shot request, retried
    /// `attempts` times in all. `None` after the last timeout.
    pub(super) fn try_transact(
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

    /// [`Self::try_transact`] with the configured retries; a timeout is an error.
    pub(super) fn transact(&mut self, cmd: Config, want: Want) -> Result<Reply, BusError> {
        let attempts = 1 + self.cfg.timing.retries;
        self.try_transact(cmd, want, attempts)?
            .ok_or_else(|| self.timeout_error(want.dev_id, &cmd.param, attempts))
    }

    pub(super) fn timeout_error(&self, dev_id: u8, param: &ConfigParam, attempts: u32) -> BusError {
        let t0 = Instant::now();
        let timeout = self.link.clock.reply_deadline(t0) - t0;
        BusError::Timeout {
            dev_id,
            what: describe(param),
            attempts,
            timeout_us: timeout.as_micros() as u64,
        }
    }

    /// Writes frames of a one-shot request that expect no reply.
    pub(super) fn job_send(&mut self, cmds: &[Command]) -> Result<(), BusError> {
        self.before_job_frame()?;
        self.link.send(cmds).map_err(|e| self.lost(e))?;
        Ok(())
    }

    /// Before each frame of a one-shot request: let waiting setpoints out
    /// (after its first frame), wait for the line, and give way to an e-stop.
    fn before_job_frame(&mut self) -> Result<(), BusError> {
        if self.job_frames > 0 && !self.exclusive {
            self.interleave_control()?;
        }
        self.job_frames += 1;
        self.wait_until(self.link.clock.write_at())?;
        self.housekeeping(Instant::now());
        if self.estop_pending() && !self.exclusive {
            return Err(BusError::Preempted);
        }
        if !self.link.is_up() {
            return Err(self.down_error());
        }
        Ok(())
    }

    fn interleave_control(&mut self) -> Result<(), BusError> {
        self.collect_setpoints();
        for _ in 0..MAX_INTERLEAVED {
            if self.pending.is_empty() || self.estop_pending() {
                break;
            }
            self.wait_until(self.link.clock.write_at())?;
            if !self.send_control()? {
                break;
            }
        }
        Ok(())
    }
}

/// What a config frame does, for error messages.
pub(super) fn describe(param: &ConfigParam) -> String {
    let (index, value) = param.index_value();
    match param {
        ConfigParam::ReadInfo(block) => format!("read {block:?}"),
        _ => format!("write index {index} = {value}"),
    }
}
