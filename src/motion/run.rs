//! A move in progress, shared by the API that made it and the bus owners
//! that stream it: the path, the instant all its joints leave, and a status
//! every party updates (a joint arrived, was replaced, the move was stopped
//! or aborted). A std `Mutex`: it is never held across an `.await`.

use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use serde::Serialize;
use utoipa::ToSchema;

use super::path::Path;

/// Where a move stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum MoveState {
    /// Its joints are following the path.
    Running,
    /// Every joint that still followed it reached the end.
    Done,
    /// Stopped by its caller (`DELETE`): each joint holds where it was.
    Stopped,
    /// Cut short (see `reason`): `estopped`, `disabled`, `reset`,
    /// `mode_changed`, `fault`, `reenabled`, `zero_moved`, or a joint offline.
    Aborted,
    /// Every joint settled, and at least one stalled: it could not follow
    /// the path (blocked) and holds where it stood (see `stalled`).
    Stalled,
}

/// A move's status as the API reports it.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct MoveStatus {
    pub state: MoveState,
    /// Why it was aborted or stopped.
    pub reason: Option<String>,
    /// Joints (by index in the move) a newer move or setpoint took over:
    /// they left this move, the others went on.
    pub replaced: Vec<usize>,
    /// Joints (by index) that reached the end of the path.
    pub arrived: Vec<usize>,
    /// Joints (by index) that stalled: held where they stood.
    pub stalled: Vec<usize>,
    /// When the move ended (its progress stops counting there).
    #[serde(skip)]
    pub ended_at: Option<Instant>,
}

/// A move the bus owners stream.
#[derive(Debug)]
pub struct RunningMove {
    pub id: u64,
    pub path: Path,
    /// When every joint leaves its start (the same instant on every bus);
    /// brought forward once what the move waits for is done
    /// ([`Self::begin_at`]).
    start: Mutex<Instant>,
    /// Before its start each joint is held where the path begins (where
    /// it stood): a move that waits before it leaves (a grasp handing back
    /// its current limit) takes the joint at once and holds it there.
    pub holds_before_start: bool,
    status: Mutex<MoveStatus>,
}

impl RunningMove {
    pub fn new(id: u64, path: Path, start: Instant) -> Self {
        Self::starting(id, path, start, false)
    }

    /// A move that may wait before it leaves: its joints held at the
    /// path's start until [`Self::begin_at`] (or `start`, at the latest).
    pub fn held(id: u64, path: Path, start: Instant) -> Self {
        Self::starting(id, path, start, true)
    }

    fn starting(id: u64, path: Path, start: Instant, holds_before_start: bool) -> Self {
        Self {
            id,
            path,
            start: Mutex::new(start),
            holds_before_start,
            status: Mutex::new(MoveStatus {
                state: MoveState::Running,
                reason: None,
                replaced: Vec::new(),
                arrived: Vec::new(),
                stalled: Vec::new(),
                ended_at: None,
            }),
        }
    }

    fn lock(&self) -> MutexGuard<'_, MoveStatus> {
        self.status.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// When every joint leaves its start.
    pub fn start(&self) -> Instant {
        *self.start.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Brings the start forward to `at` (never later than it was: a bus
    /// owner may already sample the path from the old start).
    pub fn begin_at(&self, at: Instant) {
        let mut start = self.start.lock().unwrap_or_else(|p| p.into_inner());
        *start = (*start).min(at);
    }

    pub fn status(&self) -> MoveStatus {
        self.lock().clone()
    }

    pub fn is_running(&self) -> bool {
        self.lock().state == MoveState::Running
    }

    /// Share of the path's time gone at `now` (0..=1); a move that ended
    /// keeps the share it had then.
    pub fn progress(&self, now: Instant) -> f64 {
        let now = self.lock().ended_at.map_or(now, |end| end.min(now));
        let total = self.path.duration().as_secs_f64();
        if total <= 0.0 {
            return 1.0;
        }
        (now.saturating_duration_since(self.start()).as_secs_f64() / total).clamp(0.0, 1.0)
    }

    /// Time since the start at `t` (zero before it).
    pub fn elapsed_at(&self, t: Instant) -> Duration {
        t.saturating_duration_since(self.start())
    }

    /// Joint `joint` reached the end; the move is done when every joint
    /// still in it has. Returns true when that made it done.
    pub fn arrived(&self, joint: usize) -> bool {
        let mut s = self.lock();
        if !s.arrived.contains(&joint) {
            s.arrived.push(joint);
        }
        self.finish_if_all_in(&mut s)
    }

    /// Joint `joint` was taken over by a newer move or setpoint. Returns
    /// true when that ended the move (no joint left in it).
    pub fn replaced(&self, joint: usize) -> bool {
        let mut s = self.lock();
        if s.state != MoveState::Running {
            return false;
        }
        if !s.replaced.contains(&joint) {
            s.replaced.push(joint);
        }
        self.finish_if_all_in(&mut s)
    }

    /// Joint `joint` stalled: it left the path where it stood. Returns
    /// true when that ended the move.
    pub fn stalled(&self, joint: usize) -> bool {
        let mut s = self.lock();
        if s.state != MoveState::Running {
            return false;
        }
        if !s.stalled.contains(&joint) {
            s.stalled.push(joint);
        }
        self.finish_if_all_in(&mut s)
    }

    fn finish_if_all_in(&self, s: &mut MoveStatus) -> bool {
        let settled = s.arrived.len() + s.replaced.len() + s.stalled.len();
        if s.state == MoveState::Running && settled >= self.path.joints() {
            s.state = if s.stalled.is_empty() {
                MoveState::Done
            } else {
                MoveState::Stalled
            };
            s.ended_at = Some(Instant::now());
            return true;
        }
        false
    }

    /// Ends the move as `state` (stopped or aborted) with `reason`, unless
    /// it had ended already. Returns true when this call ended it.
    pub fn end(&self, state: MoveState, reason: impl Into<String>) -> bool {
        let mut s = self.lock();
        if s.state != MoveState::Running {
            return false;
        }
        s.state = state;
        s.reason = Some(reason.into());
        s.ended_at = Some(Instant::now());
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::Method;

    fn two_joints() -> RunningMove {
        let path = Path::to(
            Method::Linear,
            vec![0.0, 0.0],
            vec![1.0, 1.0],
            Duration::from_millis(100),
        )
        .unwrap();
        RunningMove::new(7, path, Instant::now())
    }

    #[test]
    fn a_start_is_only_ever_brought_forward() {
        let later = Instant::now() + Duration::from_secs(2);
        let m = RunningMove::held(1, two_joints().path, later);
        let sooner = Instant::now() + Duration::from_millis(5);
        m.begin_at(sooner);
        assert_eq!(m.start(), sooner);
        m.begin_at(later);
        assert_eq!(m.start(), sooner, "never pushed back");
        assert!(m.holds_before_start);
    }

    #[test]
    fn a_move_is_done_when_every_joint_arrived_or_was_replaced() {
        let m = two_joints();
        assert!(!m.arrived(0));
        assert!(m.is_running());
        assert!(m.replaced(1));
        let s = m.status();
        assert_eq!(s.state, MoveState::Done);
        assert_eq!((s.arrived, s.replaced), (vec![0], vec![1]));
    }

    #[test]
    fn the_first_end_wins() {
        let m = two_joints();
        assert!(m.end(MoveState::Aborted, "e-stop"));
        assert!(!m.end(MoveState::Stopped, "stopped by its caller"));
        assert!(!m.arrived(0));
        let s = m.status();
        assert_eq!(s.state, MoveState::Aborted);
        assert_eq!(s.reason.as_deref(), Some("e-stop"));
    }
}
