//! The joints of this bus that follow a move ([`crate::motion`]): which
//! move, which of its joints, at what speed limit. The owner samples each
//! path at every control cycle, at the instant the next control frame
//! reaches the wire, and writes the positions into the setpoint store like
//! any client would; so soft limits (checked on the whole path before the
//! move started), coalescing and wire acks are the same as for setpoints.
//!
//! A client setpoint for a joint takes it out of its move (the move goes on
//! for the others); an e-stop, or a joint going offline or faulting, aborts
//! the whole move.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::motion::{MoveState, RunningMove};
use crate::protocol::units;

use super::registry::Registry;
use super::setpoints::{Setpoint, SetpointStore};
use super::state::BusEvent;

/// One joint of this bus following a move.
#[derive(Debug, Clone)]
pub struct Follower {
    pub dev_id: u8,
    pub mv: Arc<RunningMove>,
    /// The joint's index in the move's path.
    pub joint: usize,
    /// The speed limit each of its frames carries (raw).
    pub spd_ref: i16,
}

/// The followers of one bus (std `Mutex`: never held across an `.await`).
#[derive(Debug, Default)]
pub struct BusMotion {
    followers: Mutex<Vec<Follower>>,
    /// When the owner last said how far the running moves are.
    progress_said: Mutex<Option<Instant>>,
    /// True while any joint follows a move: the owner's check per decision
    /// costs one atomic load when nothing moves.
    active: AtomicBool,
}

impl BusMotion {
    fn lock(&self) -> MutexGuard<'_, Vec<Follower>> {
        self.followers.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Puts `followers` on their joints, taking each joint out of the move
    /// it followed before; returns the ids of those earlier moves.
    pub fn follow(&self, followers: Vec<Follower>) -> Vec<u64> {
        let ids: Vec<u8> = followers.iter().map(|f| f.dev_id).collect();
        let mut replaced = self.release(&ids);
        let mut list = self.lock();
        list.extend(followers);
        self.active.store(!list.is_empty(), Ordering::Release);
        replaced.dedup();
        replaced
    }

    /// Takes `ids` out of the moves they follow (a newer setpoint or move
    /// took them over); returns those moves' ids.
    pub fn release(&self, ids: &[u8]) -> Vec<u64> {
        if !self.active.load(Ordering::Acquire) {
            return Vec::new();
        }
        let mut list = self.lock();
        let mut moves = Vec::new();
        list.retain(|f| {
            if !ids.contains(&f.dev_id) {
                return true;
            }
            f.mv.replaced(f.joint);
            moves.push(f.mv.id);
            false
        });
        self.active.store(!list.is_empty(), Ordering::Release);
        moves
    }

    /// Aborts every move a joint of this bus follows (an e-stop, the bus
    /// lost); returns the ids of the moves this call ended.
    pub fn abort_all(&self, reason: &str) -> Vec<u64> {
        let mut list = self.lock();
        let mut ended = Vec::new();
        for f in list.drain(..) {
            if f.mv.end(MoveState::Aborted, reason) {
                ended.push(f.mv.id);
            }
        }
        self.active.store(false, Ordering::Release);
        ended
    }

    /// The moves this bus's joints follow, once each.
    fn moves(list: &[Follower]) -> Vec<Arc<RunningMove>> {
        let mut moves: Vec<Arc<RunningMove>> = Vec::new();
        for f in list {
            if !moves.iter().any(|m| m.id == f.mv.id) {
                moves.push(f.mv.clone());
            }
        }
        moves
    }

    pub fn is_active(&self) -> bool {
        self.active.load(Ordering::Acquire)
    }

    /// The owner's step: every follower's position at `wire_at` (when the
    /// next control frame reaches the wire) written to `store`; joints that
    /// arrived leave; a move whose joint went offline or faulted is aborted
    /// (an event says so). Moves stopped or aborted elsewhere are dropped.
    pub(crate) fn tick(
        &self,
        wire_at: Instant,
        store: &SetpointStore,
        reg: &Registry,
        events: &mut Vec<BusEvent>,
    ) {
        if !self.is_active() {
            return;
        }
        let mut list = self.lock();
        self.say_progress(&list, wire_at, reg.bus(), events);
        let mut targets: Vec<(u8, Setpoint)> = Vec::with_capacity(list.len());
        let mut aborted: Vec<(Arc<RunningMove>, String)> = Vec::new();
        let mut done: Vec<u64> = Vec::new();
        list.retain(|f| {
            if !f.mv.is_running() {
                return false;
            }
            if let Some(why) = unfit(reg, f.dev_id) {
                aborted.push((f.mv.clone(), format!("joint {} {why}", f.dev_id)));
                return false;
            }
            if wire_at < f.mv.start {
                return true;
            }
            let t = f.mv.elapsed_at(wire_at);
            let sample = f.mv.path.sample(f.joint, t);
            if let Ok(pos_ref) = units::angle_to_raw(sample.position) {
                targets.push((
                    f.dev_id,
                    Setpoint {
                        pos_ref,
                        spd_ref: f.spd_ref,
                    },
                ));
            }
            let arrived = t >= f.mv.path.duration();
            if arrived && f.mv.arrived(f.joint) {
                done.push(f.mv.id);
            }
            !arrived
        });
        for move_id in done {
            events.push(BusEvent::MoveDone {
                bus: reg.bus().to_string(),
                move_id,
            });
        }
        for (mv, reason) in aborted {
            if mv.end(MoveState::Aborted, reason.clone()) {
                events.push(BusEvent::MoveAborted {
                    bus: reg.bus().to_string(),
                    move_id: mv.id,
                    reason,
                });
            }
        }
        // The other joints of an aborted move stop too.
        list.retain(|f| f.mv.is_running());
        self.active.store(!list.is_empty(), Ordering::Release);
        drop(list);
        if !targets.is_empty() {
            store.set(&targets);
        }
    }
}

impl BusMotion {
    /// Every [`PROGRESS_EVERY`]: how far each running move of this bus is.
    fn say_progress(&self, list: &[Follower], now: Instant, bus: &str, events: &mut Vec<BusEvent>) {
        let mut said = self.progress_said.lock().unwrap_or_else(|p| p.into_inner());
        if said.is_some_and(|at| now < at + PROGRESS_EVERY) {
            return;
        }
        *said = Some(now);
        for mv in Self::moves(list).iter().filter(|m| m.is_running()) {
            events.push(BusEvent::MoveProgress {
                bus: bus.to_string(),
                move_id: mv.id,
                progress: mv.progress(now),
            });
        }
    }
}

/// How often a running move's progress is published.
pub(crate) const PROGRESS_EVERY: Duration = Duration::from_millis(100);

/// Why a joint can no longer follow a path, if it cannot.
fn unfit(reg: &Registry, id: u8) -> Option<&'static str> {
    let entry = reg.get(id)?;
    if !entry.state.online {
        return Some("went offline");
    }
    match entry.state.info01 {
        Some((info, _)) if info.err_code != 0 => Some("reported a fault"),
        _ => None,
    }
}

/// How often the owner samples paths at most: a control frame takes this
/// long on the wire at 500000 baud; sampling faster only rewrites the store.
pub(crate) const MIN_SAMPLE_INTERVAL: Duration = Duration::from_micros(400);
