//! The pipeline's side of confirmed writes ([`super::super::confirm`]):
//! where the port says when the adapter took a write, each write waits to
//! be seen taken before the next, and the wire model follows what the
//! port's count says.

use std::time::{Duration, Instant};

use super::super::confirm::{Outcome, EARLY_LOOK, MAX_WAITED};
use super::super::guard::{Change, Evidence, PipelineMode};
use super::{UsbPipeline, UNCLOCKED_LOOKS_PER_FRAME};

impl UsbPipeline {
    /// Whether the port says when the adapter took a write.
    pub(crate) fn set_port_confirms(&mut self, on: bool) {
        self.port_confirms = on;
        if !on {
            self.confirm.reset();
        }
    }

    /// True while writes are confirmed ([`super::confirm`]): the port
    /// can tell and the guard has not backed off (a backed-off guard holds
    /// the wire for each write's reach, blind). The frame clock is not
    /// needed: a host too busy to learn it (replies read late, scattered)
    /// is the host most likely to write late, and the count still says
    /// when each write was taken.
    pub(crate) fn confirming(&self) -> bool {
        self.port_confirms && self.guard.mode() == PipelineMode::Pipelined
    }

    /// Writes seen taken late, and counts given up on, since start.
    pub(crate) fn confirm_counts(&self) -> (u64, u64) {
        (self.confirm.late, self.confirm.gave_up)
    }

    /// The same, since the last call.
    pub(crate) fn take_confirm_counts(&mut self) -> (u64, u64) {
        self.confirm.take_counts()
    }

    /// True while a write waits to be seen taken: read the port's count
    /// and pass it to [`Self::confirm`] before deciding the next slot.
    pub(crate) fn awaiting_confirmation(&self) -> bool {
        self.confirm.waiting()
    }

    /// True while the write waited for is overdue ([`super::confirm`]):
    /// an e-stop may be written behind it.
    pub(crate) fn confirmation_overdue(&self) -> bool {
        self.confirm.overdue()
    }

    /// The write just made was waited for: its reply or deadline settled it.
    pub(crate) fn exchange_settled(&mut self) {
        self.confirm.reset();
    }

    /// The port's count of bytes not yet taken read `unsent` at `now`.
    /// Returns how far the wire model moves (the write left later than
    /// it had), and a change of mode when the count was given up on.
    pub(crate) fn confirm(
        &mut self,
        unsent: Option<usize>,
        now: Instant,
    ) -> (Duration, Option<Change>) {
        let period = self.period();
        let phase = &self.phase;
        let outcome = self.confirm.look(unsent, now, period, |t| {
            if phase.known() {
                phase.boundary_after(t)
            } else {
                // No clock to say where the next frame starts: look again
                // a quarter frame on; the wire is held from that look.
                t + period / UNCLOCKED_LOOKS_PER_FRAME
            }
        });
        let (by, poll, change) = match outcome {
            Outcome::Wait => return (Duration::ZERO, None),
            Outcome::OnClock { lead } => {
                // Only a write made as early as writes lead their boundary
                // shows no boundary lies where a leading write would be
                // taken early.
                if lead >= self.lead() {
                    self.clock_checks = self.clock_checks.saturating_add(1);
                }
                return (Duration::ZERO, None);
            }
            Outcome::TakenEarly { .. } => {
                // Off by most of a frame: writes wait for the wire to be
                // free until the clock holds again for a run of writes.
                self.clock_checks = 0;
                return (Duration::ZERO, None);
            }
            // A write the adapter is slow to take is still waited for:
            // blind writes would do worse on such a path, so the guard
            // stays; only a count that does not fall at all backs it off.
            Outcome::Taken { by, poll }
            | Outcome::Moved { by, poll }
            | Outcome::GaveUp { by, poll } => (by, poll, None),
            Outcome::Abandoned { by, poll } => {
                let change = self
                    .guard
                    .incident(Evidence::Untaken { after: MAX_WAITED }, now);
                (by, poll, change)
            }
        };
        if poll && !by.is_zero() {
            if let Some(last) = self.inflight.back_mut() {
                last.window.due += by;
                last.window.deadline += by;
                last.on_time = last.on_time.map(|t| t + by);
                if let Some(r) = last.packet_ref.as_mut() {
                    r.reply_end += by;
                }
            }
        }
        (by, change)
    }

    /// A write was handed over at `handed` (before [`Self::track`] of its
    /// poll, if it carries one): while writes are confirmed, it is waited
    /// to be seen taken.
    pub(crate) fn written(&mut self, handed: Instant) {
        if !self.confirming() {
            return;
        }
        if self.active() {
            let boundary = self.phase.boundary_after(handed);
            let early = boundary
                .checked_sub(self.period().mul_f64(EARLY_LOOK))
                .filter(|&at| at > handed);
            self.confirm
                .written(boundary, boundary.saturating_duration_since(handed), early);
        } else {
            // Held as late as an unclocked write may leave; looked at then.
            // A clock learnt again is checked again before writes lead it.
            self.clock_checks = 0;
            self.confirm
                .written_unclocked(self.latest_release(handed).at);
        }
    }
}
