//! The owner's wire primitives: listening, writing the frames the
//! scheduler planned, telemetry polls and request/response exchanges,
//! each feeding the scheduler what happened (frames sent, replies,
//! timeouts, the port lost). A frame is handed to the port when the
//! scheduler's line model says the line is about to free; after a request
//! that expects a reply, nothing is written until the reply arrives or its
//! deadline passes (`reply_wait`). A one-shot request's frames go through
//! `job`.

use std::time::Instant;

use crate::bus::authority::Revoked;
use crate::bus::coalesce::Planned;
use crate::bus::config::StartPolicy;
use crate::bus::error::BusError;
use crate::bus::registry::ReplyEffect;
use crate::bus::reply_lag::Seen;
use crate::bus::wire::Want;
use crate::protocol::{Command, Config, InfoBlock, Reply};

use super::Ctx;

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
        let (handed, end) = self.write(&behind(control, cmd), true)?;
        let read_before = self.link.read_before_write();
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

mod job;
mod reply_wait;
#[cfg(test)]
mod tests;
