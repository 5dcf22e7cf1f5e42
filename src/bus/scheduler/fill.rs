//! How the scheduler fills a free wire: setpoints within the control
//! budget, a poll, setpoints in front of a poll on a latent adapter, or
//! listening; and the control frame prepared while a reply is on the wire.

use std::time::Instant;

use super::{Scheduler, Slot, CONTROL_ONLY_PER_POLL, IDLE_TICK, MAX_BATCHED};
use crate::bus::coalesce::Planned;
use crate::bus::setpoints::SetpointStore;

impl Scheduler {
    /// Setpoints within budget, else a poll, else setpoints, else listen.
    /// A prepared frame is good for this decision only, and only if no
    /// setpoint came in since it was planned.
    pub(super) fn wire_slot(&mut self, now: Instant, store: &SetpointStore) -> Slot {
        // Behind a USB adapter a write carries a poll (with the control
        // frames in front), whether it is timed by the frame clock or waits
        // for its reply: without replies the frame clock is never learnt.
        // Only a backed-off pipeline adds control-only transfers between
        // polls, and setpoints go alone when there is nothing to poll.
        if self.pipeline.is_some() {
            return self.pipelined_slot(now, store);
        }
        if let Some((frame, seq)) = self.control.take_prepared(store) {
            if self.budget.allows(now) {
                if seq == store.latest_seq() {
                    return self.control_slot(now, frame);
                }
                if let Some(frame) = self.plan_control(now, store) {
                    return self.control_slot(now, frame);
                }
            }
        }
        self.control.collect(store);
        if self.control.has_pending() && self.budget.allows(now) {
            if let Some(frame) = self.plan_control(now, store) {
                return self.control_slot(now, frame);
            }
        }
        let timeout = self.clock.reply_timeout(now);
        if let Some(poll) = self.planner.next(self.reg.poll_states(), now, timeout) {
            let control = self.batch_control(store);
            if !control.is_empty() {
                return Slot::Batch {
                    control,
                    dev_id: poll.dev_id,
                    block: poll.block,
                };
            }
            return Slot::Poll {
                dev_id: poll.dev_id,
                block: poll.block,
            };
        }
        self.control_or_listen(now, store)
    }

    /// A control frame on a native line, and in the same write the poll
    /// that must follow it when the budget will not allow another control
    /// frame once this one has left the line: the owner then sleeps once
    /// per control frame and poll, not twice (on a VM a wake-up costs more
    /// of a core than everything else the owner does for a frame). The
    /// frames are on the wire in the same order and at the same times as
    /// written one by one. A setpoint arriving while the control frame is
    /// on the wire would have waited for the poll anyway (the budget chose
    /// it); a request or an e-stop arriving then waits for the poll's
    /// reply too: up to one transaction (0.9 ms at 500000 baud) later.
    fn control_slot(&mut self, now: Instant, frame: Planned) -> Slot {
        if self.budget.allows_another(now, self.clock.frame_time()) {
            return Slot::Control(frame);
        }
        let timeout = self.clock.reply_timeout(now);
        match self.planner.next(self.reg.poll_states(), now, timeout) {
            Some(poll) => Slot::Batch {
                control: vec![frame],
                dev_id: poll.dev_id,
                block: poll.block,
            },
            None => Slot::Control(frame),
        }
    }

    /// Behind a USB adapter (the write time was waited for in
    /// [`Self::next`]): one transfer a cycle, the pending control frames and
    /// the next poll; its reply is left in flight, matched when the adapter
    /// hands it over.
    /// Guarded (a transfer with a poll holds the wire a frame longer), a
    /// transfer of control frames only goes before each poll when any are
    /// pending: control keeps its rate, telemetry gives way.
    fn pipelined_slot(&mut self, now: Instant, store: &SetpointStore) -> Slot {
        let guarded = self
            .pipeline
            .as_ref()
            .is_some_and(|p| p.guard().control_between_polls());
        if guarded && self.control_only < CONTROL_ONLY_PER_POLL {
            let control = self.batch_control(store);
            if !control.is_empty() {
                self.control_only += 1;
                return Slot::ControlBatch(control);
            }
        }
        let free_at = self.clock.free_at();
        let sentinel = match self.pipeline.as_mut() {
            Some(pipeline) if pipeline.sentinel_due() => {
                // A sentinel is handed over late in its frame: until then
                // the bus listens (an e-stop or a request still goes first).
                if let Some(until) = pipeline.sentinel_wait(free_at, now) {
                    return Slot::Listen { until };
                }
                true
            }
            _ => false,
        };
        let timeout = self.clock.reply_timeout(now);
        if let Some(poll) = self.planner.next(self.reg.poll_states(), now, timeout) {
            self.control_only = 0;
            if let Some(pipeline) = self.pipeline.as_mut().filter(|_| sentinel) {
                pipeline.arm_sentinel();
            }
            return Slot::Batch {
                control: self.batch_control(store),
                dev_id: poll.dev_id,
                block: poll.block,
            };
        }
        self.control_or_listen(now, store)
    }

    /// Nothing to poll: setpoints if any are pending, else listen a tick.
    fn control_or_listen(&mut self, now: Instant, store: &SetpointStore) -> Slot {
        match self.plan_control(now, store) {
            Some(frame) => Slot::Control(frame),
            None => Slot::Listen {
                until: now + IDLE_TICK,
            },
        }
    }

    /// On a latent adapter, the control frames (at most [`MAX_BATCHED`])
    /// that ride in front of a poll: a USB round trip costs a millisecond or
    /// more, a frame on the wire 0.4 ms. None on a native line, where the
    /// round trip is the wire's.
    fn batch_control(&mut self, store: &SetpointStore) -> Vec<Planned> {
        // Not held to the control budget: frames in front of a poll cost it
        // 0.4 ms each against a round trip of a millisecond or more.
        if !self.clock.adapter().is_latent() {
            return Vec::new();
        }
        self.control.collect(store);
        let (frames, dropped) = self.control.plan_up_to(&self.reg, store, MAX_BATCHED);
        self.dropped += u64::from(dropped);
        frames
    }

    /// Collects and plans the frame carrying the oldest pending setpoint.
    pub(super) fn plan_control(&mut self, now: Instant, store: &SetpointStore) -> Option<Planned> {
        self.control.collect(store);
        let (frame, dropped) = self.control.plan(&self.reg, store, now);
        self.dropped += u64::from(dropped);
        frame
    }

    /// While a reply is on the wire (due at `due`): plan the control frame
    /// that follows it, so the line idles no longer than needed after the
    /// reply. The next decision uses it if no setpoint came in meanwhile.
    pub(crate) fn prepare(&mut self, due: Instant, store: &SetpointStore) {
        self.control.collect(store);
        let latest = store.latest_seq();
        let frame = if self.control.has_pending() && self.budget.allows(due) {
            self.plan_control(due, store).map(|frame| (frame, latest))
        } else {
            None
        };
        self.control.set_prepared(frame);
    }

    /// A control frame from [`Slot::Control`] (or an interleave) left for
    /// the wire, its last byte due at `end`: charged to the budget, its
    /// setpoints settled.
    pub(crate) fn control_sent(&mut self, frame: &Planned, end: Instant) {
        self.budget.spend(self.clock.frame_time());
        self.control.sent(frame, &mut self.reg, end);
    }
}
