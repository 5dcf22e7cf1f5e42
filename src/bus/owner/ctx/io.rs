//! The owner's wire primitives: listening, writing the frames the
//! scheduler planned, telemetry polls, and the request/response
//! transactions one-shot requests are made of. Each feeds the scheduler
//! what happened (frames sent, replies, timeouts, the port lost).
//!
//! Every frame is handed to the port when the scheduler's line model says
//! the line is about to free; after a request that expects a reply,
//! nothing is written until the reply arrives or its deadline passes.

use std::time::{Duration, Instant};

use crate::bus::authority::Revoked;
use crate::bus::coalesce::Planned;
use crate::bus::config::StartPolicy;
use crate::bus::error::BusError;
use crate::bus::owner::confirm::describe;
use crate::bus::registry::ReplyEffect;
use crate::bus::reply_lag::Seen;
use crate::bus::wire::{ReplyWindow, Want};
use crate::protocol::{Command, Config, ConfigParam, InfoBlock, Reply};

use super::Ctx;

/// With `reply_spin_us = 0` (no spinning): how long before a reply is due
/// the owner wakes to plan the next control frame: ample for planning,
/// short enough that the setpoints it samples are fresh.
const PREPARE_LEAD: Duration = Duration::from_micros(100);
/// How often a reply wait past its modelled time looks for an e-stop.
const LATE_WAIT_SLICE: Duration = Duration::from_millis(1);

impl Ctx {
    /// Listens until `at`; replies nobody waited for are taken in.
    pub(crate) fn wait_until(&mut self, at: Instant) -> Result<(), BusError> {
        let waited = self.link.wait(None, at);
        self.absorb_inbox();
        waited.map(|_| ()).map_err(|e| self.lost(e))
    }

    /// Replies no transaction waited for: those of polls written blind
    /// (matched here), power-up announcements, late replies.
    pub(crate) fn absorb_inbox(&mut self) {
        self.learn_frame_clock();
        let inbox = std::mem::take(&mut self.link.inbox);
        for (i, heard) in inbox.iter().enumerate() {
            let reply = &heard.reply;
            let followed_by = inbox[i + 1..]
                .iter()
                .filter(|h| h.reply.dev_id == reply.dev_id && h.reply.index == reply.index)
                .count();
            let effect = match self
                .sched
                .take_inflight(reply, followed_by, heard.first_byte)
            {
                Some(inflight) => {
                    self.stats
                        .round_trip(heard.at.saturating_duration_since(inflight.handed));
                    self.sched
                        .inflight_reply(reply, heard.at, &inflight, heard.packet)
                }
                None => {
                    self.link.counters.unsolicited += 1;
                    self.sched.unsolicited(reply, heard.at)
                }
            };
            self.after_reply(reply.dev_id, effect);
        }
        self.link.inbox = inbox;
        self.link.inbox.clear();
    }

    /// Hands the scheduler the instants the port woke this thread with
    /// bytes (a USB adapter's frame boundaries, each seen as late as the
    /// thread wakes) and how late it wakes.
    fn learn_frame_clock(&mut self) {
        let lag = self.link.wake_lateness();
        self.sched.set_arrival_lag(lag);
        for at in self.link.take_woke_on_bytes() {
            self.sched.arrival(at);
        }
    }

    /// Hands host frames to the port; returns when the last one leaves the wire.
    pub(crate) fn send(&mut self, cmds: &[Command]) -> Result<Instant, BusError> {
        Ok(self.write(cmds, true)?.1)
    }

    /// [`Self::send`] of control frames only: no reply follows them.
    fn send_without_reply(&mut self, cmds: &[Command]) -> Result<Instant, BusError> {
        Ok(self.write(cmds, false)?.1)
    }

    /// Hands host frames to the port: when it took them, dated after the
    /// write (a thread preempted before it must not look like a path that
    /// delivered them late), and when the last one leaves the wire, the
    /// wire held as for a write that `asks_reply` or not.
    fn write(
        &mut self,
        cmds: &[Command],
        asks_reply: bool,
    ) -> Result<(Instant, Instant), BusError> {
        let handed = self.link.send(cmds).map_err(|e| self.lost(e))?;
        let n = cmds.len() as u32;
        let end = if asks_reply {
            self.sched.sent(handed, n)
        } else {
            self.sched.sent_without_reply(handed, n)
        };
        Ok((handed, end))
    }

    /// Accounts control frames written in front of the last frame of a
    /// write that ended on the wire at `end` (each one frame earlier).
    fn control_frames_sent(&mut self, control: &[Planned], end: Instant) {
        let frame = self.sched.clock().frame_time();
        let n = control.len() as u32;
        for (i, planned) in control.iter().enumerate() {
            let its_end = end - frame * (n - i as u32);
            for (_, sp) in &planned.carries {
                self.stats
                    .setpoint_age(its_end.saturating_duration_since(sp.accepted));
                self.link.counters.setpoints_sent += 1;
            }
            self.sched.control_sent(planned, its_end);
        }
        if n > 0 {
            self.after_decision();
        }
    }

    /// Writes a control frame the scheduler planned.
    pub(crate) fn send_planned(&mut self, frame: Planned) -> Result<(), BusError> {
        let end = self.send_without_reply(&[frame.command])?;
        for (_, sp) in &frame.carries {
            self.stats
                .setpoint_age(end.saturating_duration_since(sp.accepted));
            self.link.counters.setpoints_sent += 1;
        }
        self.sched.control_sent(&frame, end);
        self.after_decision();
        Ok(())
    }

    /// Control frames in one write, no poll (a backed-off USB pipeline).
    pub(crate) fn send_control_batch(&mut self, frames: Vec<Planned>) -> Result<(), BusError> {
        let cmds: Vec<Command> = frames.iter().map(|p| p.command).collect();
        let end = self.send_without_reply(&cmds)?;
        self.link.counters.frames_tx_batched += frames.len() as u64;
        self.control_frames_sent(&frames, end);
        Ok(())
    }

    /// One telemetry poll the scheduler picked.
    pub(crate) fn poll(&mut self, dev_id: u8, block: InfoBlock) -> Result<(), BusError> {
        self.poll_behind(Vec::new(), dev_id, block)
    }

    /// A poll with control frames in front of it, all in one write (one USB
    /// transfer on a latent adapter): the frames leave back to back and the
    /// poll's reply follows the last.
    pub(crate) fn poll_behind(
        &mut self,
        control: Vec<Planned>,
        dev_id: u8,
        block: InfoBlock,
    ) -> Result<(), BusError> {
        self.link.counters.polls += 1;
        let want = Want {
            dev_id,
            index: block.index(),
        };
        if self.sched.pipelining() {
            return self.poll_blind(&control, Config::read(dev_id, block), want);
        }
        self.exchange_behind(&control, Config::read(dev_id, block), want)?;
        Ok(())
    }

    /// Behind a USB adapter: writes the control frames and the poll as one
    /// transfer and goes on without waiting;
    /// the reply is matched when the adapter hands it over (`absorb_inbox`)
    /// or counted missing at its deadline (`expire_inflight`).
    fn poll_blind(&mut self, control: &[Planned], cmd: Config, want: Want) -> Result<(), BusError> {
        let clocked = self.sched.usb_clock_known();
        let read_before = self.link.bytes_read();
        let (handed, end) = self.write(&behind(control, cmd), true)?;
        self.link.counters.frames_tx_batched += control.len() as u64;
        self.link.counters.polls_pipelined += 1;
        self.link.counters.usb_writes_unclocked += u64::from(!clocked);
        self.control_frames_sent(control, end);
        self.sched.track(want, end, (handed, read_before));
        Ok(())
    }

    /// Polls written blind whose deadline passed: missed, like a poll
    /// that timed out.
    pub(crate) fn expire_inflight(&mut self, now: Instant) {
        for inflight in self.sched.expired_inflight(now) {
            self.link.counters.timeouts += 1;
            self.sched.inflight_timed_out(&inflight, now);
        }
        self.link.counters.usb_writes_ambiguous += self.sched.take_ambiguous_writes();
        let garbled = self.link.counters.crc_errors + self.link.counters.skipped_bytes;
        self.sched.usb_watch(garbled, now);
        let (sentinels, late) = self.sched.take_sentinel_counts();
        self.link.counters.usb_sentinels += sentinels;
        self.link.counters.usb_sentinels_late += late;
        let (taken_late, given_up) = self.sched.take_confirm_counts();
        self.link.counters.usb_writes_taken_late += taken_late;
        self.link.counters.usb_counts_given_up += given_up;
        for change in self.sched.take_usb_changes() {
            self.usb_changed(&change);
        }
    }

    /// One WARN per change of the USB pipeline's mode, never per frame.
    fn usb_changed(&mut self, change: &crate::bus::usb::guard::Change) {
        let c = &mut self.link.counters;
        if change.backed_off {
            c.usb_backoffs += 1;
            tracing::warn!(
                bus = %self.cfg.name, from = %change.from, to = %change.to,
                reason = %change.reason,
                "USB pipeline backed off: writes reach the adapter later than assumed"
            );
        } else {
            c.usb_recoveries += 1;
            tracing::warn!(
                bus = %self.cfg.name, from = %change.from, to = %change.to,
                reason = %change.reason,
                "USB pipeline stepped back towards the adapter's bound"
            );
        }
    }

    /// Writes one config/read frame and waits for the reply it asks for;
    /// with `prepare`, has the next control frame planned meanwhile. `None`
    /// when the reply did not come in time (counted as a missed poll);
    /// [`BusError::Preempted`] when an e-stop cut the wait short (the frame
    /// went out, its effect is unknown).
    fn exchange(
        &mut self,
        cmd: Config,
        want: Want,
        prepare: bool,
    ) -> Result<Option<Reply>, BusError> {
        self.exchange_as(cmd, want, prepare, Silence::Missed)
    }

    /// [`Self::exchange`] of a poll behind `control` frames, one write.
    fn exchange_behind(
        &mut self,
        control: &[Planned],
        cmd: Config,
        want: Want,
    ) -> Result<Option<Reply>, BusError> {
        self.exchange_with(control, cmd, want, true, Silence::Missed)
    }

    fn exchange_as(
        &mut self,
        cmd: Config,
        want: Want,
        prepare: bool,
        silence: Silence,
    ) -> Result<Option<Reply>, BusError> {
        self.exchange_with(&[], cmd, want, prepare, silence)
    }

    fn exchange_with(
        &mut self,
        control: &[Planned],
        cmd: Config,
        want: Want,
        prepare: bool,
        silence: Silence,
    ) -> Result<Option<Reply>, BusError> {
        let started = Instant::now();
        let (handed, end) = self.write(&behind(control, cmd), true)?;
        self.link.counters.frames_tx_batched += control.len() as u64;
        self.control_frames_sent(control, end);
        let window = self.sched.reply_window(end);
        let sliced_from = self.sliced_from(window, end);
        // Where replies have been coming, not where the model puts them.
        let aim = window.due + self.reply_lag.lag();
        let mut got = self.sleep_before_reply(want, aim, sliced_from);
        if prepare && matches!(got, Ok(None)) {
            // Planned in the moments before the reply, after the one wake-up
            // a transaction costs: its setpoints are as fresh as they can be.
            self.sched.prepare(window.due, &self.shared.setpoints);
        }
        let mut seen = Seen::Bound;
        if matches!(got, Ok(None)) {
            (got, seen) = self.wait_reply(want, window, aim, sliced_from);
        }
        if let Ok(Some((_, read_at))) = &got {
            self.reply_lag.observe(window.due, *read_at, seen);
        }
        self.absorb_inbox();
        let got = got.map_err(|e| self.lost(e))?;
        let now = Instant::now();
        if got.is_none() && self.estop_pending() && now < window.deadline {
            // Given up for the e-stop, not missed: the reply may still
            // come out of the adapter, and is then taken in as a late one.
            self.sched.given_up(want, window.due, now);
            return Err(BusError::Preempted);
        }
        if let Some((_, read_at)) = &got {
            self.stats
                .round_trip(read_at.saturating_duration_since(started));
            self.sched.waited_reply(end, handed, *read_at);
        }
        Ok(self.settle_exchange(got, want, window.due, silence))
    }

    /// From when a wait for the reply to a request ending at `end` goes in
    /// short slices that give way to an e-stop: a frame after the modelled
    /// reply, or from the e-stop cut-in (the reply off the wire, held by a
    /// latency timer) if that is sooner. A late, missing or held reply must
    /// not hold an e-stop back, nor the snapshot; nor may the owner's aim
    /// at where replies have been coming (up to
    /// [`crate::bus::reply_lag::MAX_LAG`] past the model).
    fn sliced_from(&self, window: ReplyWindow, end: Instant) -> Instant {
        let grace = window.due + self.sched.clock().frame_time();
        self.sched.estop_cut_in(end).map_or(grace, |c| c.min(grace))
    }

    /// Waits for `want` until the window's deadline, watching the port from
    /// `aim` (the modelled time plus the lag replies have shown); in
    /// slices from `sliced_from` (see [`Self::sliced_from`]). Says whether
    /// the reply came while the port was watched.
    fn wait_reply(
        &mut self,
        want: Want,
        window: ReplyWindow,
        aim: Instant,
        sliced_from: Instant,
    ) -> (std::io::Result<Option<(Reply, Instant)>>, Seen) {
        if self.estop_pending() && Instant::now() >= sliced_from {
            return (Ok(None), Seen::Bound);
        }
        let (mut got, mut seen) = self.spin_for_reply(want, aim, sliced_from);
        if matches!(got, Ok(None)) {
            // A reply from here on wakes the thread: it may have come
            // before it was read.
            seen = Seen::Bound;
            got = self.link.wait(Some(want), sliced_from.min(window.deadline));
        }
        (self.wait_sliced(want, got, window.deadline, true), seen)
    }

    /// Goes on waiting for `want` until `until` while `got` is empty, in
    /// slices of [`LATE_WAIT_SLICE`] that give way to an e-stop; with
    /// `housekeeping`, the snapshot and expiries are kept up between them.
    fn wait_sliced(
        &mut self,
        want: Want,
        mut got: std::io::Result<Option<(Reply, Instant)>>,
        until: Instant,
        housekeeping: bool,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        while matches!(got, Ok(None)) && !self.estop_pending() {
            let now = Instant::now();
            if now >= until {
                break;
            }
            if housekeeping {
                self.housekeeping(now);
            }
            got = self.link.wait(Some(want), until.min(now + LATE_WAIT_SLICE));
        }
        got
    }

    /// Blocks until shortly before `due`, where the reply is expected: by
    /// as much as this thread is seen to wake late (learnt by the link from
    /// every timed read), when it spins for the reply next
    /// ([`Self::spin_for_reply`]); by [`PREPARE_LEAD`] when it does not.
    /// Past `sliced_from` (see [`Self::sliced_from`]) it sleeps in short
    /// slices and gives way to an e-stop.
    fn sleep_before_reply(
        &mut self,
        want: Want,
        due: Instant,
        sliced_from: Instant,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        let lead = match self.cfg.timing.reply_spin_us > 0 {
            true => self.link.wake_lateness(),
            false => PREPARE_LEAD,
        };
        let until = due.checked_sub(lead).unwrap_or(due);
        let got = self.link.wait(Some(want), sliced_from.min(until));
        self.wait_sliced(want, got, until, false)
    }

    /// Looks at the port without sleeping until `reply_spin_us` past `aim`
    /// (where the reply is expected): a thread woken from sleep (on a VM, a
    /// halted virtual CPU woken too) reacts tens of µs later, and every
    /// poll's reply would be followed by such a gap on the line. A reply
    /// found after an empty look arrived when it was found. Past
    /// `sliced_from` it gives way to an e-stop.
    fn spin_for_reply(
        &mut self,
        want: Want,
        aim: Instant,
        sliced_from: Instant,
    ) -> (std::io::Result<Option<(Reply, Instant)>>, Seen) {
        let spin = Duration::from_micros(self.cfg.timing.reply_spin_us);
        if spin.is_zero() {
            return (Ok(None), Seen::Bound);
        }
        let mut got = self.link.poll_now(Some(want));
        let mut seen = Seen::Bound;
        while matches!(got, Ok(None)) {
            let now = Instant::now();
            if now >= aim + spin || (now >= sliced_from && self.estop_pending()) {
                break;
            }
            std::hint::spin_loop();
            seen = Seen::Watching;
            got = self.link.poll_now(Some(want));
        }
        (got, seen)
    }

    /// Takes in the reply of an exchange, or counts it missing.
    fn settle_exchange(
        &mut self,
        got: Option<(Reply, Instant)>,
        want: Want,
        due: Instant,
        silence: Silence,
    ) -> Option<Reply> {
        // Its reply, or its deadline, settles the write: the wire model
        // follows the exchange, not the port's count read after it.
        self.sched.exchange_settled();
        self.learn_frame_clock();
        let Some((reply, at)) = got else {
            match silence {
                Silence::Missed => {
                    self.link.counters.timeouts += 1;
                    self.sched.timed_out(want, due, Instant::now());
                }
                Silence::Answer => {
                    self.link.counters.firmware_probes_unanswered += 1;
                    self.sched.unanswered(want, due, Instant::now());
                }
            }
            return None;
        };
        let effect = self.sched.reply(&reply, at, due);
        self.after_reply(reply.dev_id, effect);
        Some(reply)
    }

    /// What a reply means for the store: a device that reset or faulted
    /// holds no target, and none written before may reach it later (the
    /// scheduler already forgot what was pending). Rare: nothing is done
    /// here for an ordinary reply.
    fn after_reply(&mut self, id: u8, effect: ReplyEffect) {
        let store = &self.shared.setpoints;
        if effect.reset {
            store.revoke(Some(&[id]), Revoked::Reset);
            if effect.powered_up {
                // A power-up runs position mode (SPEC §4.1: the mode is not saved).
                store.authority().mode_set(id, None);
            }
        } else if effect.faulted {
            store.revoke(Some(&[id]), Revoked::Fault);
        }
        if effect.found_enabled && self.cfg.on_start == StartPolicy::Keep {
            // Kept enabled by the configuration's choice: commands may drive it.
            let epoch = store.authority().grant(id).epoch;
            store.authority().arm(id, epoch);
        }
        self.resend_if_aligned(id, effect);
    }

    /// A joint that just finished aligning gets its latest target again,
    /// through the store like any client write (a newer write wins): only
    /// one written since its enable, which cleared the store.
    fn resend_if_aligned(&mut self, id: u8, effect: ReplyEffect) {
        if !effect.now_running {
            return;
        }
        if let Some(latest) = self.shared.setpoints.get(id) {
            // What went out during align does not count as on the device.
            self.sched.registry_mut().forget_target(id);
            self.shared.setpoints.set_admitted(
                &[(id, latest.setpoint, latest.epoch)],
                crate::bus::setpoints::Source::Aligned,
            );
        }
    }

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
        self.try_transact(cmd, want, attempts)?
            .ok_or_else(|| self.timeout_error(want.dev_id, &cmd.param, attempts))
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

/// What a missing reply means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Silence {
    /// The device should have answered: a timeout, a missed poll.
    Missed,
    /// Silence is an answer (a firmware probe).
    Answer,
}

/// `control` frames and then `cmd`, as one write.
fn behind(control: &[Planned], cmd: Config) -> Vec<Command> {
    control
        .iter()
        .map(|p| p.command)
        .chain([Command::Config(cmd)])
        .collect()
}

#[cfg(test)]
mod tests;
