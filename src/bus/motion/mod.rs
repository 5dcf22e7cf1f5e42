//! The joints of this bus that follow a move ([`crate::motion`]): which
//! move, which of its joints, at what speed limit. The owner samples each
//! path at every control cycle, at the instant the next control frame
//! reaches the wire, and writes the positions into the setpoint store like
//! any client would (one write per move, its source the move); so soft
//! limits (checked on the whole path before the move started), coalescing,
//! wire acks and recordings are the same as for setpoints. When the path
//! has ended, its goal is written once: the last sample inside the path
//! falls short of it by up to a control cycle's travel.
//!
//! A client setpoint for a joint takes it out of its move (the move goes on
//! for the others). Each follower carries the motion epoch its move was
//! admitted under: when the joint's epoch advances (e-stop, disable, reset,
//! fault, mode change, enable) the whole move is aborted with that reason,
//! and its samples could not reach the joint anyway (the owner drops them).
//! A joint going offline aborts the move too.
//!
//! A joint that cannot follow (blocked by an object or a stop) stalls
//! ([`stall`]: its samples stay off the path and it barely moves), during
//! the path or after its end. It leaves the move `stalled` and holds where
//! it stands (its target becomes its measured angle). A joint arrives when
//! the path has ended and its measured angle is within [`ARRIVED_DEG`] of
//! the goal.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::motion::{MoveState, RunningMove};
use crate::protocol::units;

use super::authority::Epoch;
use super::events::BusEvent;
use super::registry::Registry;
use super::setpoints::{Setpoint, SetpointStore, Source};

mod stall;

use stall::{Sampled, StallWatch, Verdict};

/// A joint this far from its goal after the path's end has arrived.
pub(crate) const ARRIVED_DEG: f64 = 1.0;

/// One joint of this bus following a move.
#[derive(Debug, Clone)]
pub struct Follower {
    pub dev_id: u8,
    pub mv: Arc<RunningMove>,
    /// The joint's index in the move's path.
    pub joint: usize,
    /// The speed limit each of its frames carries (raw).
    pub spd_ref: i16,
    /// The motion epoch the move was admitted under on this joint.
    pub epoch: Epoch,
    /// Whether the joint keeps up with its path.
    stall: StallWatch,
    /// The path's goal has been written (once, after the path's end).
    goal_written: bool,
}

impl Follower {
    pub fn new(dev_id: u8, mv: Arc<RunningMove>, joint: usize, spd_ref: i16, epoch: Epoch) -> Self {
        Self {
            dev_id,
            mv,
            joint,
            spd_ref,
            epoch,
            stall: StallWatch::default(),
            goal_written: false,
        }
    }
}

/// What taking joints out of their moves did.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Released {
    /// The moves the joints left.
    pub left: Vec<u64>,
    /// Those of them that ended: every joint had left, arrived or stalled.
    pub ended: Vec<u64>,
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
    pub fn follow(&self, followers: Vec<Follower>) -> Released {
        let ids: Vec<u8> = followers.iter().map(|f| f.dev_id).collect();
        let replaced = self.release(&ids);
        let mut list = self.lock();
        list.extend(followers);
        self.active.store(!list.is_empty(), Ordering::Release);
        replaced
    }

    /// Takes `ids` out of the moves they follow (a newer setpoint or move
    /// took them over); returns those moves' ids, and those of the moves
    /// this ended (no joint left in them).
    pub fn release(&self, ids: &[u8]) -> Released {
        let mut out = Released::default();
        if !self.active.load(Ordering::Acquire) {
            return out;
        }
        let mut list = self.lock();
        list.retain(|f| {
            if !ids.contains(&f.dev_id) {
                return true;
            }
            if f.mv.replaced(f.joint) {
                out.ended.push(f.mv.id);
            }
            out.left.push(f.mv.id);
            false
        });
        self.active.store(!list.is_empty(), Ordering::Release);
        out.left.dedup();
        out
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

    /// True while joint `id` follows a move.
    pub fn follows(&self, id: u8) -> bool {
        self.is_active() && self.lock().iter().any(|f| f.dev_id == id)
    }

    /// The owner's step: every follower's position at `wire_at` (when the
    /// next control frame reaches the wire) written to `store` under the
    /// epoch its move was admitted with; joints that arrived or stalled
    /// leave; a move whose joint's epoch advanced, or whose joint went
    /// offline, is aborted (an event says so). Moves stopped or aborted
    /// elsewhere are dropped.
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
        let mut step = Step::default();
        list.retain_mut(|f| follow_one(f, wire_at, store, reg, &mut step));
        for move_id in step.done {
            events.push(BusEvent::MoveDone {
                bus: reg.bus().to_string(),
                move_id,
            });
        }
        for (mv, reason) in step.aborted {
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
        // One write per move (usually one), so each says whose it is. A
        // joint follows one move, so the order between moves is free.
        let mut targets = step.targets;
        targets.sort_by_key(|(move_id, _)| *move_id);
        for run in targets.chunk_by(|a, b| a.0 == b.0) {
            let this: Vec<_> = run.iter().map(|(_, t)| *t).collect();
            store.set_admitted(&this, Source::Move { move_id: run[0].0 });
        }
    }
}

/// What one owner step decided for the followers.
#[derive(Default)]
struct Step {
    /// Targets, each with the id of the move it comes from.
    targets: Vec<(u64, (u8, Setpoint, Epoch))>,
    aborted: Vec<(Arc<RunningMove>, String)>,
    /// Moves that ended (every joint arrived, stalled or left).
    done: Vec<u64>,
}

/// One follower's step; false when it leaves its move.
fn follow_one(
    f: &mut Follower,
    wire_at: Instant,
    store: &SetpointStore,
    reg: &Registry,
    step: &mut Step,
) -> bool {
    if !f.mv.is_running() {
        return false;
    }
    if let Some(why) = revoked(store, f) {
        step.aborted.push((f.mv.clone(), why));
        return false;
    }
    if let Some(why) = unfit(reg, f.dev_id) {
        step.aborted
            .push((f.mv.clone(), format!("joint {} {why}", f.dev_id)));
        return false;
    }
    if wire_at < f.mv.start() {
        if f.mv.holds_before_start {
            push(f, f.mv.path.sample(f.joint, Duration::ZERO).position, step);
        }
        return true;
    }
    let t = f.mv.elapsed_at(wire_at);
    let sample = f.mv.path.sample(f.joint, t);
    let measured = reg.get(f.dev_id).and_then(|e| e.measured);
    let ended = t >= f.mv.path.duration();
    if ended && !f.goal_written {
        f.goal_written = true;
        push(f, sample.position, step);
    }
    let off = measured.map(|(m, _)| (units::angle_deg(m) - sample.position).abs());
    if ended && off.is_some_and(|d| d <= ARRIVED_DEG) {
        if f.mv.arrived(f.joint) {
            step.done.push(f.mv.id);
        }
        return false;
    }
    if !running(reg, f.dev_id) {
        f.stall.pause();
    } else if let Some((raw, at)) = measured {
        let seen = Sampled {
            deg: units::angle_deg(raw),
            at,
        };
        if f.stall.look(&f.mv, f.joint, seen) == Verdict::Stalled {
            return stall(f, Some(raw), step);
        }
    }
    if !ended {
        push(f, sample.position, step);
    }
    true
}

/// The follower's target at `position_deg` (device frame), at its speed limit.
fn push(f: &Follower, position_deg: f64, step: &mut Step) {
    if let Ok(pos_ref) = units::angle_to_raw(position_deg) {
        let sp = Setpoint {
            pos_ref,
            spd_ref: f.spd_ref,
        };
        step.targets.push((f.mv.id, (f.dev_id, sp, f.epoch)));
    }
}

/// The joint leaves its move holding where it stands.
fn stall(f: &Follower, measured: Option<i16>, step: &mut Step) -> bool {
    if let Some(pos_ref) = measured {
        let hold = Setpoint {
            pos_ref,
            spd_ref: f.spd_ref,
        };
        step.targets.push((f.mv.id, (f.dev_id, hold, f.epoch)));
    }
    if f.mv.stalled(f.joint) {
        step.done.push(f.mv.id);
    }
    false
}

/// The joint's last INFO_01 shows it running (not aligning: a joint that
/// aligns stands still, which is no stall).
fn running(reg: &Registry, id: u8) -> bool {
    reg.get(id)
        .and_then(|e| e.state.info01)
        .is_some_and(|(info, _)| info.fsm == crate::protocol::status::fsm::RUN)
}

/// Why the follower's move may no longer drive its joint, if its epoch advanced.
fn revoked(store: &SetpointStore, f: &Follower) -> Option<String> {
    let authority = store.authority();
    if authority.admits(f.dev_id, f.epoch) {
        return None;
    }
    Some(
        authority
            .last_revoked(f.dev_id)
            .map_or("disabled", |r| r.name())
            .to_string(),
    )
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

/// Why a joint can no longer follow a path, if it cannot (a fault is
/// seen by the epoch: the owner revokes a joint that faults).
fn unfit(reg: &Registry, id: u8) -> Option<&'static str> {
    let entry = reg.get(id)?;
    if !entry.state.online {
        return Some("went offline");
    }
    None
}

/// How often the owner samples paths at most: a control frame takes this
/// long on the wire at 500000 baud; sampling faster only rewrites the store.
pub(crate) const MIN_SAMPLE_INTERVAL: Duration = Duration::from_micros(400);
