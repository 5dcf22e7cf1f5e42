//! The bench's hand and the numbers it is judged by: the fingers and
//! where their objects stand, speeds, the hold current, timing, the goals.

use std::time::Duration;

pub(super) const HAND: &str = "bench";
pub(super) const FINGERS: [(u8, &str, f64); 3] =
    [(1, "f1", 10.0), (2, "f2", 15.0), (3, "f3", 20.0)];
pub(super) const CLOSE_TO_DEG: f64 = 45.0;
pub(super) const SPEED_DPS: f64 = 30.0;
/// A faster closing on the stiff object, reported but not judged.
pub(super) const FAST_DPS: f64 = 60.0;
pub(super) const HOLD_A: f64 = 0.2;
/// Soft and stiff objects, N·m per degree.
pub(super) const STIFFNESS: [f64; 2] = [0.01, 0.1];
pub(super) const RUNS_PER_CASE: usize = 8;
pub(super) const FREE_AIR_RUNS: usize = 100;
pub(super) const FREE_AIR_CLOSE_DEG: f64 = 12.0;
/// The hold is judged from this long after the last contact, over `WINDOW`.
pub(super) const SETTLE: Duration = Duration::from_millis(300);
pub(super) const WINDOW: Duration = Duration::from_millis(1000);
pub(super) const SAMPLE: Duration = Duration::from_millis(1);
pub(super) const RUN_WAIT: Duration = Duration::from_secs(15);
/// At rest after a release: this slow and this close to the target.
pub(super) const REST_DEG_S: f64 = 0.5;
pub(super) const REST_DEG: f64 = 0.05;
/// Goals: overshoot and steady-state error, % of the hold setting.
pub(super) const MAX_OVERSHOOT_PCT: f64 = 20.0;
pub(super) const MAX_HOLD_ERROR_PCT: f64 = 10.0;
