//! Synchronised multi-joint paths: every joint of a move leaves its start
//! together and arrives together, along one normalised shape (linear,
//! minimum-jerk, trapezoidal velocity), through timed waypoints.
//!
//! Pure: a path is sampled at a time since its start; the bus engine does
//! that at every control cycle (`bus::motion`).

use std::time::Duration;

use serde::{Deserialize, Serialize};
use thiserror::Error;
use utoipa::ToSchema;

/// How a joint goes from one waypoint to the next.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Constant velocity: leaves and arrives at speed (a step in velocity).
    Linear,
    /// Minimum jerk (Flash & Hogan): `10s³ − 15s⁴ + 6s⁵`; starts and ends
    /// at rest with zero acceleration.
    #[default]
    MinJerk,
    /// Trapezoidal velocity: a third of the time accelerating, a third at
    /// constant speed, a third braking; starts and ends at rest.
    Trapezoid,
}

/// Peak of the normalised velocity of each shape (distance 1 in time 1).
const PEAK_VELOCITY: [f64; 3] = [1.0, 1.875, 1.5];
/// Peak of the normalised acceleration (`10/√3` for minimum jerk).
const PEAK_ACCELERATION: [f64; 3] = [0.0, 5.773_502_691_896_258, 4.5];

impl Method {
    fn index(self) -> usize {
        match self {
            Self::Linear => 0,
            Self::MinJerk => 1,
            Self::Trapezoid => 2,
        }
    }

    /// Position and velocity of the shape at `s` in `0..=1` (distance 1 in time 1).
    pub fn shape(self, s: f64) -> (f64, f64) {
        let s = s.clamp(0.0, 1.0);
        match self {
            Self::Linear => (s, 1.0),
            Self::MinJerk => {
                let (s2, s3) = (s * s, s * s * s);
                (
                    s3 * (10.0 - 15.0 * s + 6.0 * s2),
                    30.0 * s2 * (1.0 - 2.0 * s + s2),
                )
            }
            Self::Trapezoid => {
                if s <= 1.0 / 3.0 {
                    (2.25 * s * s, 4.5 * s)
                } else if s <= 2.0 / 3.0 {
                    (0.25 + 1.5 * (s - 1.0 / 3.0), 1.5)
                } else {
                    let r = 1.0 - s;
                    (1.0 - 2.25 * r * r, 4.5 * r)
                }
            }
        }
    }

    /// The shortest time a joint may take for `distance` (degrees) under
    /// `max_velocity` (°/s) and `max_acceleration` (°/s²); `None` bounds
    /// nothing. Linear has an infinite acceleration at its ends, so only
    /// the velocity bounds it.
    pub fn shortest(
        self,
        distance: f64,
        max_velocity: Option<f64>,
        max_acceleration: Option<f64>,
    ) -> f64 {
        let d = distance.abs();
        let by_velocity = max_velocity.map_or(0.0, |v| PEAK_VELOCITY[self.index()] * d / v);
        let by_acceleration = match (self, max_acceleration) {
            (Self::Linear, _) | (_, None) => 0.0,
            (_, Some(a)) => (PEAK_ACCELERATION[self.index()] * d / a).sqrt(),
        };
        by_velocity.max(by_acceleration)
    }

    /// The peak speed (°/s) of a joint covering `distance` in `seconds`.
    pub fn peak_velocity(self, distance: f64, seconds: f64) -> f64 {
        PEAK_VELOCITY[self.index()] * distance.abs() / seconds.max(f64::EPSILON)
    }
}

/// What makes a path impossible.
#[derive(Debug, Error, PartialEq)]
pub enum PathError {
    #[error("a move needs at least one waypoint")]
    NoWaypoint,
    #[error("waypoint {index} has {got} positions for {joints} joints")]
    Width {
        index: usize,
        got: usize,
        joints: usize,
    },
    #[error("waypoint {index} is at {at_ms} ms, not after the one before")]
    NotAfter { index: usize, at_ms: f64 },
    #[error("position {value} of waypoint {index} is not a finite number")]
    NotFinite { index: usize, value: f64 },
}

/// A synchronised path of several joints: the start positions, then
/// waypoints each reached by every joint at its time.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    method: Method,
    start: Vec<f64>,
    /// (time since start, positions), times strictly increasing.
    waypoints: Vec<(Duration, Vec<f64>)>,
}

/// One joint's position (°) and velocity (°/s) at an instant of a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub position: f64,
    pub velocity: f64,
}

impl Path {
    /// A path from `start` (one position per joint) through `waypoints`.
    pub fn new(
        method: Method,
        start: Vec<f64>,
        waypoints: Vec<(Duration, Vec<f64>)>,
    ) -> Result<Self, PathError> {
        if waypoints.is_empty() {
            return Err(PathError::NoWaypoint);
        }
        let mut last = Duration::ZERO;
        for (index, (at, positions)) in waypoints.iter().enumerate() {
            if positions.len() != start.len() {
                return Err(PathError::Width {
                    index,
                    got: positions.len(),
                    joints: start.len(),
                });
            }
            if *at <= last {
                return Err(PathError::NotAfter {
                    index,
                    at_ms: at.as_secs_f64() * 1e3,
                });
            }
            if let Some(value) = positions.iter().find(|p| !p.is_finite()) {
                return Err(PathError::NotFinite {
                    index,
                    value: *value,
                });
            }
            last = *at;
        }
        Ok(Self {
            method,
            start,
            waypoints,
        })
    }

    /// A move of every joint from `start` to `target` in `duration`.
    pub fn to(
        method: Method,
        start: Vec<f64>,
        target: Vec<f64>,
        duration: Duration,
    ) -> Result<Self, PathError> {
        Self::new(method, start, vec![(duration, target)])
    }

    pub fn joints(&self) -> usize {
        self.start.len()
    }

    pub fn method(&self) -> Method {
        self.method
    }

    /// When the last waypoint is reached.
    pub fn duration(&self) -> Duration {
        self.waypoints.last().map_or(Duration::ZERO, |(at, _)| *at)
    }

    /// Every position the path passes through at a waypoint or its start:
    /// the shapes are monotone between two waypoints, so a limit that holds
    /// at these holds on the whole path.
    pub fn extremes(&self, joint: usize) -> impl Iterator<Item = f64> + '_ {
        std::iter::once(&self.start)
            .chain(self.waypoints.iter().map(|(_, p)| p))
            .filter_map(move |p| p.get(joint).copied())
    }

    /// The highest speed (°/s) any joint reaches.
    pub fn peak_velocity(&self) -> f64 {
        (0..self.joints())
            .map(|j| self.peak_velocity_of(j))
            .fold(0.0, f64::max)
    }

    /// The highest speed (°/s) joint `joint` reaches.
    pub fn peak_velocity_of(&self, joint: usize) -> f64 {
        let mut from = (Duration::ZERO, value(&self.start, joint));
        let mut peak: f64 = 0.0;
        for (at, positions) in &self.waypoints {
            let seconds = (*at - from.0).as_secs_f64();
            let to = value(positions, joint);
            peak = peak.max(self.method.peak_velocity(to - from.1, seconds));
            from = (*at, to);
        }
        peak
    }

    /// Joint `joint` at `t` after the start (held at the last waypoint after it).
    pub fn sample(&self, joint: usize, t: Duration) -> Sample {
        let mut from = (Duration::ZERO, &self.start);
        for (at, positions) in &self.waypoints {
            if t < *at {
                let span = (*at - from.0).as_secs_f64();
                let s = (t.saturating_sub(from.0)).as_secs_f64() / span;
                let (a, b) = (value(from.1, joint), value(positions, joint));
                let (p, v) = self.method.shape(s);
                return Sample {
                    position: a + (b - a) * p,
                    velocity: (b - a) * v / span,
                };
            }
            from = (*at, positions);
        }
        Sample {
            position: value(from.1, joint),
            velocity: 0.0,
        }
    }
}

fn value(positions: &[f64], joint: usize) -> f64 {
    positions.get(joint).copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const METHODS: [Method; 3] = [Method::Linear, Method::MinJerk, Method::Trapezoid];

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn every_shape_goes_from_0_to_1_continuously_and_monotonically() {
        for m in METHODS {
            assert_eq!(m.shape(0.0).0, 0.0, "{m:?}");
            assert!((m.shape(1.0).0 - 1.0).abs() < 1e-12, "{m:?}");
            let mut last = 0.0;
            for k in 1..=10_000 {
                let (p, v) = m.shape(f64::from(k) / 10_000.0);
                assert!(p >= last - 1e-12, "{m:?} not monotone at {k}");
                // Continuous: no step larger than the peak speed allows.
                assert!(
                    p - last <= PEAK_VELOCITY[m.index()] / 10_000.0 + 1e-9,
                    "{m:?} {k}"
                );
                assert!(
                    v >= 0.0 && v <= PEAK_VELOCITY[m.index()] + 1e-9,
                    "{m:?} {k}"
                );
                last = p;
            }
        }
    }

    #[test]
    fn min_jerk_and_trapezoid_start_and_end_at_rest_and_velocity_is_the_slope() {
        for m in [Method::MinJerk, Method::Trapezoid] {
            assert_eq!(m.shape(0.0).1, 0.0, "{m:?}");
            assert!(m.shape(1.0).1.abs() < 1e-12, "{m:?}");
        }
        for m in METHODS {
            for k in 1..99 {
                let s = f64::from(k) / 100.0;
                let h = 1e-6;
                let slope = (m.shape(s + h).0 - m.shape(s - h).0) / (2.0 * h);
                assert!((slope - m.shape(s).1).abs() < 1e-3, "{m:?} at {s}");
            }
        }
    }

    #[test]
    fn all_joints_leave_together_and_arrive_together_on_time() {
        let path = Path::to(
            Method::MinJerk,
            vec![0.0, 10.0, -30.0],
            vec![90.0, 10.0, 30.0],
            ms(800),
        )
        .unwrap();
        assert_eq!(path.duration(), ms(800));
        for j in 0..3 {
            let start = path.sample(j, Duration::ZERO);
            assert_eq!(start.position, [0.0, 10.0, -30.0][j]);
            assert_eq!(start.velocity, 0.0);
            let end = path.sample(j, ms(800));
            assert_eq!(end.position, [90.0, 10.0, 30.0][j]);
            // Within a control period (~2 ms) of the end, within 0.05° of it.
            let near = path.sample(j, ms(798));
            assert!((near.position - end.position).abs() < 0.05, "{near:?}");
        }
        // Halfway, every moving joint is halfway (same shape, same time).
        assert!((path.sample(0, ms(400)).position - 45.0).abs() < 1e-9);
        assert!((path.sample(2, ms(400)).position - 0.0).abs() < 1e-9);
    }

    #[test]
    fn limits_give_the_shortest_duration_and_the_path_respects_them() {
        for m in METHODS {
            let d = 90.0;
            let (vmax, amax) = (200.0, 2000.0);
            let t = m.shortest(d, Some(vmax), Some(amax));
            let path = Path::to(m, vec![0.0], vec![d], Duration::from_secs_f64(t)).unwrap();
            let mut peak_v: f64 = 0.0;
            let mut peak_a: f64 = 0.0;
            let dt = 1e-4;
            let mut last_v = path.sample(0, Duration::ZERO).velocity;
            let mut k = 1;
            while f64::from(k) * dt < t {
                let v = path
                    .sample(0, Duration::from_secs_f64(f64::from(k) * dt))
                    .velocity;
                peak_v = peak_v.max(v.abs());
                peak_a = peak_a.max(((v - last_v) / dt).abs());
                last_v = v;
                k += 1;
            }
            assert!(peak_v <= vmax * 1.001, "{m:?}: {peak_v}");
            if m != Method::Linear {
                assert!(peak_a <= amax * 1.01, "{m:?}: {peak_a}");
                // And it is the shortest: one of the two limits is reached.
                assert!(peak_v >= vmax * 0.99 || peak_a >= amax * 0.95, "{m:?}");
            }
        }
    }

    #[test]
    fn waypoints_are_reached_at_their_times() {
        let path = Path::new(
            Method::Trapezoid,
            vec![0.0],
            vec![
                (ms(300), vec![20.0]),
                (ms(500), vec![-10.0]),
                (ms(900), vec![0.0]),
            ],
        )
        .unwrap();
        assert_eq!(path.sample(0, ms(300)).position, 20.0);
        assert_eq!(path.sample(0, ms(500)).position, -10.0);
        assert_eq!(path.sample(0, ms(2000)).position, 0.0);
        assert_eq!(
            path.extremes(0).collect::<Vec<_>>(),
            vec![0.0, 20.0, -10.0, 0.0]
        );
        // 30° in 200 ms at a trapezoid's 1.5x mean speed.
        assert!((path.peak_velocity() - 1.5 * 30.0 / 0.2).abs() < 1e-9);
    }

    #[test]
    fn impossible_paths_are_refused_with_the_reason() {
        assert_eq!(
            Path::new(Method::Linear, vec![0.0], vec![]),
            Err(PathError::NoWaypoint)
        );
        assert!(matches!(
            Path::new(Method::Linear, vec![0.0], vec![(ms(100), vec![1.0, 2.0])]),
            Err(PathError::Width { got: 2, .. })
        ));
        assert!(matches!(
            Path::new(
                Method::Linear,
                vec![0.0],
                vec![(ms(100), vec![1.0]), (ms(100), vec![2.0])]
            ),
            Err(PathError::NotAfter { index: 1, .. })
        ));
        assert!(matches!(
            Path::new(Method::Linear, vec![0.0], vec![(ms(100), vec![f64::NAN])]),
            Err(PathError::NotFinite { .. })
        ));
    }
}
