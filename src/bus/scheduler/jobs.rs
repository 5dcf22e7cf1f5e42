//! How one-shot requests share the wire: setpoints may go out between two
//! frames of a request (at most [`MAX_INTERLEAVED`](super::MAX_INTERLEAVED), so a long scan does not
//! freeze the joints), an e-stop preempts a request before its next frame,
//! and in an exclusive phase (devices and port at different bauds) neither
//! happens: an e-stop's frames would not reach everyone.

use std::time::Instant;

use crate::bus::coalesce::Planned;
use crate::bus::setpoints::SetpointStore;

use super::{JobPhase, Preempted, Scheduler, MAX_INTERLEAVED};

impl Scheduler {
    /// A one-shot request starts outside [`Scheduler::next`] (the e-stop's
    /// read-back): its frame count starts over.
    pub(crate) fn job_start(&mut self) {
        self.job = JobPhase {
            exclusive: self.job.exclusive,
            ..JobPhase::default()
        };
    }

    /// Before the next frame of a request, with the line free at `now`: a
    /// setpoint frame to write first, if one may go out.
    pub(crate) fn interleave(
        &mut self,
        now: Instant,
        store: &SetpointStore,
        estop_generation: u64,
    ) -> Option<Planned> {
        let job = self.job;
        let allowed = job.frames > 0 && !job.exclusive && job.interleaved < MAX_INTERLEAVED;
        if !allowed || self.estop_pending(estop_generation) {
            return None;
        }
        self.control.clear_prepared();
        let frame = self.plan_control(now, store)?;
        self.job.interleaved += 1;
        Some(frame)
    }

    /// The request's next frame is about to be written: counted, unless an
    /// e-stop waits (outside an exclusive phase), which the request must
    /// give way to.
    pub(crate) fn job_frame(&mut self, estop_generation: u64) -> Result<(), Preempted> {
        self.job.frames += 1;
        self.job.interleaved = 0;
        if self.estop_pending(estop_generation) && !self.job.exclusive {
            return Err(Preempted);
        }
        Ok(())
    }

    /// Enters or leaves a phase nothing may interrupt.
    pub(crate) fn set_exclusive(&mut self, exclusive: bool) {
        self.job.exclusive = exclusive;
    }

    /// The request ended abnormally (a caught panic): no phase survives it.
    pub(crate) fn job_abort(&mut self) {
        self.job = JobPhase::default();
    }
}
