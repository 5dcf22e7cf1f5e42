//! The e-stop's slot: served ahead of everything, and from when it may
//! take the wire from a transaction behind a latency timer.

use std::time::{Duration, Instant};

use super::{Scheduler, Slot, Work};

impl Scheduler {
    /// The e-stop's slot when a press above the last one served waits; a
    /// control frame prepared for the next decision is void then.
    pub(super) fn estop_slot(&mut self, work: &Work<'_>) -> Option<Slot> {
        if !self.estop_pending(work.estop_generation) {
            return None;
        }
        self.estop_seen = work.estop_generation;
        self.control.clear_prepared();
        Some(Slot::EStop {
            generation: work.estop_generation,
        })
    }

    /// Behind a latency timer, from when an e-stop may take the wire from
    /// a transaction whose request ended at `end`: its reply has left the
    /// wire (the write late by up to the pipeline's reach) and only waits
    /// in the adapter, for as long as the timer. `None` elsewhere: there
    /// the reply reaches the host as it leaves the wire.
    pub(crate) fn estop_cut_in(&self, end: Instant) -> Option<Instant> {
        self.clock.adapter().latency_timer()?;
        let reach = self
            .pipeline
            .as_ref()
            .map_or(Duration::ZERO, |p| p.guard().reach());
        let (wire_end, _) = self.reply_out(end);
        Some(wire_end + reach)
    }

    /// True while an e-stop press above the last one served waits.
    pub(crate) fn estop_pending(&self, generation: u64) -> bool {
        generation > self.estop_seen
    }

    /// The e-stop generation served last.
    pub(crate) fn estop_seen(&self) -> u64 {
        self.estop_seen
    }
}
