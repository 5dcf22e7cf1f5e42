//! The setpoints between the store and the wire: what was taken from the
//! store and is not yet on the wire (`pending`), the frame planned while a
//! reply was on the line (`prepared`), and the sequence numbers the
//! handle's wire acks are made of.
//!
//! Pure: the store is read (never written) and every instant is passed in.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::bus::coalesce::{self, Pending, Planned};
use crate::bus::registry::Registry;
use crate::bus::setpoints::SetpointStore;
use crate::bus::state::WireAck;

/// Setpoints waiting for the wire and what has been acknowledged of them.
#[derive(Debug, Default)]
pub(super) struct Control {
    /// Setpoints taken from the store and not yet on the wire.
    pending: BTreeMap<u8, Pending>,
    /// Highest store sequence number taken into `pending`.
    seen_seq: u64,
    /// Highest sequence number all of whose joints are on the wire.
    acked_seq: u64,
    /// A control frame planned while a reply was on the wire, and the store
    /// sequence number it was planned at.
    prepared: Option<(Planned, u64)>,
    /// A wire ack not yet handed to the owner for publication.
    ack: Option<WireAck>,
}

impl Control {
    #[cfg(test)]
    pub(super) fn pending(&self) -> &BTreeMap<u8, Pending> {
        &self.pending
    }

    pub(super) fn has_pending(&self) -> bool {
        !self.pending.is_empty()
    }

    #[cfg(test)]
    pub(super) fn seen_seq(&self) -> u64 {
        self.seen_seq
    }

    #[cfg(test)]
    pub(super) fn peek_prepared(&self) -> Option<&Planned> {
        self.prepared.as_ref().map(|(frame, _)| frame)
    }

    pub(super) fn take_ack(&mut self) -> Option<WireAck> {
        self.ack.take()
    }

    /// Takes what changed in the store into `pending`. Cheap when nothing
    /// did: one atomic load, no lock.
    pub(super) fn collect(&mut self, store: &SetpointStore) {
        if store.latest_seq() <= self.seen_seq {
            return;
        }
        let mut stale = 0;
        for (id, setpoint) in store.changed_since(self.seen_seq) {
            self.seen_seq = self.seen_seq.max(setpoint.seq);
            if !store.admits(id, &setpoint) {
                stale += 1;
                continue;
            }
            let since = self.pending.get(&id).map_or(setpoint.accepted, |p| p.since);
            self.pending.insert(id, Pending { setpoint, since });
        }
        store.authority().count_stale(stale);
    }

    /// Drops pending setpoints a revoke made stale since they were taken
    /// (an e-stop pressed, a joint disabled while they waited): checked
    /// again right before a frame is made of them.
    fn drop_stale(&mut self, store: &SetpointStore) {
        let before = self.pending.len();
        self.pending.retain(|id, p| store.admits(*id, &p.setpoint));
        store
            .authority()
            .count_stale((before - self.pending.len()) as u64);
    }

    /// The prepared frame, if one was planned since the last decision and
    /// everything it carries is still admitted.
    pub(super) fn take_prepared(&mut self, store: &SetpointStore) -> Option<(Planned, u64)> {
        let (frame, seq) = self.prepared.take()?;
        let fresh = frame.carries.iter().all(|(id, sp)| store.admits(*id, sp));
        fresh.then_some((frame, seq))
    }

    pub(super) fn set_prepared(&mut self, frame: Option<(Planned, u64)>) {
        self.prepared = frame;
    }

    pub(super) fn clear_prepared(&mut self) {
        self.prepared = None;
    }

    /// The frame carrying the oldest pending setpoint; drops what needs
    /// none (already on the device, or for an id nobody answers to).
    /// Returns the frame and how many setpoints were dropped as unknown.
    pub(super) fn plan(
        &mut self,
        reg: &Registry,
        store: &SetpointStore,
        now: Instant,
    ) -> (Option<Planned>, u32) {
        self.drop_stale(store);
        if self.pending.is_empty() {
            return (None, 0);
        }
        let plan = coalesce::plan(&self.pending, |id| reg.slot_info(id));
        for (id, sp) in &plan.settled {
            self.settle(*id, sp.seq);
        }
        for id in &plan.unknown {
            self.pending.remove(id);
        }
        let first = plan.frames.into_iter().next();
        if first.is_none() {
            self.note_ack(now);
        }
        (first, plan.unknown.len() as u32)
    }

    /// Every frame the pending setpoints need, oldest first, at most `max`
    /// (for one USB transfer); drops what needs none, as [`Self::plan`].
    pub(super) fn plan_up_to(
        &mut self,
        reg: &Registry,
        store: &SetpointStore,
        max: usize,
    ) -> (Vec<Planned>, u32) {
        self.drop_stale(store);
        if self.pending.is_empty() {
            return (Vec::new(), 0);
        }
        let plan = coalesce::plan(&self.pending, |id| reg.slot_info(id));
        for (id, sp) in &plan.settled {
            self.settle(*id, sp.seq);
        }
        for id in &plan.unknown {
            self.pending.remove(id);
        }
        let frames = plan.frames.into_iter().take(max).collect();
        (frames, plan.unknown.len() as u32)
    }

    /// `frame` left for the wire, its last byte due at `end`.
    pub(super) fn sent(&mut self, frame: &Planned, reg: &mut Registry, end: Instant) {
        for (id, sp) in &frame.carries {
            reg.record_sent(*id, sp.setpoint, end);
            self.settle(*id, sp.seq);
        }
        self.note_ack(end);
    }

    /// Drops `id` from pending unless a newer setpoint replaced it meanwhile.
    fn settle(&mut self, id: u8, seq: u64) {
        if self.pending.get(&id).is_some_and(|p| p.setpoint.seq <= seq) {
            self.pending.remove(&id);
        }
    }

    /// Notes the highest sequence number all of whose joints are on the wire.
    fn note_ack(&mut self, at: Instant) {
        let oldest_pending = self.pending.values().map(|p| p.setpoint.seq).min();
        let seq = oldest_pending.map_or(self.seen_seq, |s| s.saturating_sub(1));
        if seq > self.acked_seq {
            self.acked_seq = seq;
            self.ack = Some(WireAck { seq, at: Some(at) });
        }
    }

    /// Forgets pending setpoints and skips what the store holds now.
    pub(super) fn drop_all(&mut self, store: &SetpointStore) {
        self.prepared = None;
        self.collect(store);
        self.pending.clear();
        self.acked_seq = self.seen_seq;
    }

    /// Forgets what is pending (the store keeps it, a later write resends).
    pub(super) fn clear_pending(&mut self) {
        self.pending.clear();
    }

    /// One joint's pending setpoint is void (disable, re-zero, reboot).
    pub(super) fn forget(&mut self, id: u8) {
        self.pending.remove(&id);
    }

    /// The joint's pending setpoint follows its id change.
    pub(super) fn rename(&mut self, old: u8, new: u8) {
        if let Some(sp) = self.pending.remove(&old) {
            self.pending.insert(new, sp);
        }
    }
}
