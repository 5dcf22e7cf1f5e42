//! When a homing search has found its stop, decided from the samples
//! alone, and where it must give up without one: pure rules, tested here
//! without a bus.

use std::time::{Duration, Instant};

use super::request::{Direction, Plan};
use crate::control::limits::JointLimits;

/// The joint must look stalled this long (by its samples' times).
const STALL_CONFIRM: Duration = Duration::from_millis(80);
/// Before the joint has been seen moving, a standstill counts as a stall
/// only after this long (it may start right at its stop).
const START_GRACE: Duration = Duration::from_millis(500);
/// Below this share of the asked speed the joint is not moving ...
const STALLED_SPEED_SHARE: f64 = 0.2;
/// ... above this one it is.
const MOVING_SPEED_SHARE: f64 = 0.5;
/// The q current counts as risen at this share of the reduced limit.
const PUSHING_CURRENT_SHARE: f64 = 0.6;
/// The search ends this long (at the asked speed) before a bound, so
/// that the joint, still coasting while speed 0 reaches it, stays inside.
const BOUND_LOOKAHEAD: Duration = Duration::from_millis(100);

/// One telemetry sample of a searching joint, at the output.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sample {
    /// When the device was sampled.
    pub(super) at: Instant,
    pub(super) speed_dps: f64,
    /// The q current, A.
    pub(super) current_a: f64,
}

/// A searching joint's samples, read for a stall at its stop: its speed
/// under a fifth of the asked speed for [`STALL_CONFIRM`], after it was
/// seen moving (or after [`START_GRACE`]: it may start at its stop), or
/// as slow with the q current near the reduced limit (pushing).
#[derive(Debug, Clone)]
pub(super) struct StallWatch {
    started: Instant,
    asked_dps: f64,
    current_limit_a: f64,
    moved: bool,
    stalled_since: Option<Instant>,
}

impl StallWatch {
    pub(super) fn new(started: Instant, asked_dps: f64, current_limit_a: f64) -> Self {
        Self {
            started,
            asked_dps,
            current_limit_a,
            moved: false,
            stalled_since: None,
        }
    }

    /// Takes the next sample (in time order); true once the joint has
    /// looked stalled for [`STALL_CONFIRM`] of its samples' time.
    pub(super) fn stalled(&mut self, s: Sample) -> bool {
        let speed = s.speed_dps.abs();
        self.moved |= speed > MOVING_SPEED_SHARE * self.asked_dps;
        let slow = speed < STALLED_SPEED_SHARE * self.asked_dps;
        let pushing = slow && s.current_a.abs() >= PUSHING_CURRENT_SHARE * self.current_limit_a;
        let still = slow && (self.moved || s.at.duration_since(self.started) > START_GRACE);
        if pushing || still {
            let since = *self.stalled_since.get_or_insert(s.at);
            s.at.duration_since(since) >= STALL_CONFIRM
        } else {
            self.stalled_since = None;
            false
        }
    }

    /// The joint was seen moving at least half the asked speed.
    pub(super) fn moved(&self) -> bool {
        self.moved
    }
}

/// Where the search must end without a stop: the soft limit or the
/// travel limit in the search direction, whichever comes first.
#[derive(Debug, Clone, Copy)]
pub(super) struct Bound {
    /// Device degrees.
    deg: f64,
    /// Where the search started, device degrees.
    start_deg: f64,
    /// The soft limit (not the travel) is the nearer.
    soft: bool,
    travel_deg: f64,
}

impl Bound {
    pub(super) fn new(plan: &Plan, soft: &JointLimits, start_deg: f64) -> Self {
        let travel_deg = plan.max_travel_deg.unwrap_or(soft.max_deg - soft.min_deg);
        let (by_travel, by_soft) = match plan.direction {
            Direction::Negative => (start_deg - travel_deg, soft.min_deg),
            Direction::Positive => (start_deg + travel_deg, soft.max_deg),
        };
        let soft_nearer = plan.direction.sign() * (by_travel - by_soft) >= 0.0;
        Self {
            deg: if soft_nearer { by_soft } else { by_travel },
            start_deg,
            soft: soft_nearer,
            travel_deg,
        }
    }

    /// The joint at `deg`, moving at `speed_dps` the search's way, is at
    /// the bound (or would pass it before speed 0 reaches it).
    pub(super) fn reached(&self, dir: Direction, deg: f64, speed_dps: f64) -> bool {
        let ahead = speed_dps * BOUND_LOOKAHEAD.as_secs_f64();
        dir.sign() * (self.deg - deg) <= ahead
    }

    /// Why the search failed at `deg`, in the job's words.
    pub(super) fn failure(&self, deg: f64) -> String {
        let what = if self.soft {
            format!(
                "the soft limits: the joint reached {deg:.1}° at its soft limit ({:.1}°), \
                 {:.1}° from where it started",
                self.deg,
                (deg - self.start_deg).abs()
            )
        } else {
            format!(
                "max_travel_deg = {}°: the joint reached {deg:.1}° from {:.1}°",
                self.travel_deg, self.start_deg
            )
        };
        format!("no hard stop within {what}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASKED_DPS: f64 = 10.0;
    const LIMIT_A: f64 = 0.3;

    fn at(start: Instant, ms: u64) -> Instant {
        start + Duration::from_millis(ms)
    }

    fn sample(start: Instant, ms: u64, speed_dps: f64, current_a: f64) -> Sample {
        Sample {
            at: at(start, ms),
            speed_dps,
            current_a,
        }
    }

    /// Feeds samples every 10 ms from `from_ms` to `to_ms`; the first time
    /// (ms) the watch says stalled.
    fn first_stall(
        w: &mut StallWatch,
        t0: Instant,
        from_ms: u64,
        to_ms: u64,
        speed: f64,
        current: f64,
    ) -> Option<u64> {
        (from_ms..=to_ms)
            .step_by(10)
            .find(|&ms| w.stalled(sample(t0, ms, speed, current)))
    }

    #[test]
    fn a_joint_that_moved_then_stopped_is_stalled_after_the_confirmation_time() {
        let t0 = Instant::now();
        let mut w = StallWatch::new(t0, ASKED_DPS, LIMIT_A);
        assert_eq!(first_stall(&mut w, t0, 0, 200, ASKED_DPS, 0.05), None);
        assert!(w.moved());
        let stalled = first_stall(&mut w, t0, 210, 600, 0.5, 0.05).expect("it stalls");
        assert_eq!(stalled, 210 + STALL_CONFIRM.as_millis() as u64);
    }

    #[test]
    fn a_joint_standing_still_from_the_start_is_a_stall_only_after_the_grace() {
        let t0 = Instant::now();
        let mut w = StallWatch::new(t0, ASKED_DPS, LIMIT_A);
        let stalled = first_stall(&mut w, t0, 0, 2000, 0.0, 0.0).expect("it stalls");
        let grace = START_GRACE.as_millis() as u64;
        // The first sample past the grace starts the confirmation.
        assert_eq!(stalled, grace + 10 + STALL_CONFIRM.as_millis() as u64);
        assert!(!w.moved());
    }

    #[test]
    fn pushing_at_the_reduced_limit_is_a_stall_even_before_the_grace() {
        let t0 = Instant::now();
        let mut w = StallWatch::new(t0, ASKED_DPS, LIMIT_A);
        let pushing_a = PUSHING_CURRENT_SHARE * LIMIT_A;
        let stalled = first_stall(&mut w, t0, 0, 400, 0.0, -pushing_a).expect("it pushes");
        assert_eq!(stalled, STALL_CONFIRM.as_millis() as u64);
    }

    #[test]
    fn moving_again_restarts_the_confirmation() {
        let t0 = Instant::now();
        let mut w = StallWatch::new(t0, ASKED_DPS, LIMIT_A);
        assert!(!w.stalled(sample(t0, 0, ASKED_DPS, 0.0)));
        assert!(!w.stalled(sample(t0, 10, 0.0, 0.0)));
        assert!(!w.stalled(sample(t0, 60, 0.0, 0.0)));
        // Between the two thresholds: neither moving nor stalled; it
        // still breaks the run of slow samples.
        assert!(!w.stalled(sample(t0, 70, 0.3 * ASKED_DPS, 0.0)));
        assert!(!w.stalled(sample(t0, 80, 0.0, 0.0)));
        assert!(!w.stalled(sample(t0, 150, 0.0, 0.0)));
        assert!(w.stalled(sample(t0, 160, 0.0, 0.0)));
    }

    #[test]
    fn a_reverse_speed_counts_by_its_size() {
        let t0 = Instant::now();
        let mut w = StallWatch::new(t0, ASKED_DPS, LIMIT_A);
        assert!(!w.stalled(sample(t0, 0, -ASKED_DPS, 0.0)));
        assert!(w.moved());
    }

    fn plan(direction: Direction, max_travel_deg: Option<f64>) -> Plan {
        Plan {
            direction,
            speed_dps: ASKED_DPS,
            current_limit_a: LIMIT_A,
            backoff_deg: 2.0,
            stop_at_deg: 0.0,
            max_travel_deg,
            timeout: Duration::from_secs(20),
        }
    }

    fn soft(min_deg: f64, max_deg: f64) -> JointLimits {
        JointLimits {
            min_deg,
            max_deg,
            ..JointLimits::default()
        }
    }

    #[test]
    fn the_nearer_of_the_soft_limit_and_the_travel_bounds_the_search() {
        let b = Bound::new(
            &plan(Direction::Negative, Some(20.0)),
            &soft(-90.0, 90.0),
            0.0,
        );
        assert_eq!(b.deg, -20.0);
        assert!(!b.soft);
        assert!(b.failure(-20.0).contains("max_travel_deg = 20°"));
        let b = Bound::new(
            &plan(Direction::Positive, Some(200.0)),
            &soft(-90.0, 90.0),
            0.0,
        );
        assert_eq!(b.deg, 90.0);
        assert!(b.soft);
        assert!(b.failure(90.0).contains("soft limit"));
        // No travel given: the width of the soft range.
        let b = Bound::new(&plan(Direction::Negative, None), &soft(-10.0, 50.0), 40.0);
        assert_eq!(b.deg, -10.0);
    }

    #[test]
    fn the_bound_is_reached_a_lookahead_before_it() {
        let b = Bound::new(
            &plan(Direction::Negative, Some(20.0)),
            &soft(-90.0, 90.0),
            0.0,
        );
        let ahead = ASKED_DPS * BOUND_LOOKAHEAD.as_secs_f64();
        assert!(!b.reached(Direction::Negative, -20.0 + ahead + 0.01, ASKED_DPS));
        assert!(b.reached(Direction::Negative, -20.0 + ahead - 0.01, ASKED_DPS));
        assert!(b.reached(Direction::Negative, -25.0, ASKED_DPS));
        let b = Bound::new(
            &plan(Direction::Positive, Some(20.0)),
            &soft(-90.0, 90.0),
            0.0,
        );
        assert!(!b.reached(Direction::Positive, 19.0 - ahead, ASKED_DPS));
        assert!(b.reached(Direction::Positive, 20.0, ASKED_DPS));
    }
}
