//! Position mode against current mode for grasping, at the physics level:
//! the simulated joint ([`crate::sim::physics`]) driven directly, without
//! the daemon (which has no current setpoint path: SPEC reserves the
//! control frame's `cur_ref`, and only the simulator reads it as rev
//! 2.0.8's current reference). Same objects as the grasp bench (soft and
//! stiff, at 10, 15 and 20°) and the same hold setting:
//!
//! - position mode: towards a closing limit past the object at the bench's
//!   speed with MAX_CUR at the hold setting, and the daemon's contact
//!   brake (speed limit to a tenth for 100 ms once contact is seen in the
//!   noisy measured current: over the free-air current by the default
//!   threshold while slowed, or for 10 ms);
//! - current mode: the hold setting as the current reference from the
//!   start, so the finger free-runs at the speed that current holds
//!   against friction.
//!
//! Reported per mode and stiffness (mean and worst over objects and
//! noise seeds): the speed at contact, time to contact (first touch),
//! peak push over the set force, peak measured current over the setting,
//! and the steady-state error of the push and of the measured current.
//! The physics does not depend on the firmware revision; the measured
//! current carries the reports' noise (4 mA, one sample per ms).

use crate::protocol::params::index;
use crate::protocol::units::current_limit_to_raw;
use crate::protocol::BaudLevel;
use crate::sim::object::Object;
use crate::sim::params::Params;
use crate::sim::physics::{Drive, Joint, HOLD_CURRENT_A};
use crate::sim::rng::Rng;

const HOLD_A: f64 = 0.2;
const STIFFNESS: [f64; 2] = [0.01, 0.1];
const OBJECTS_DEG: [f64; 3] = [10.0, 15.0, 20.0];
const CLOSE_TO_DEG: f64 = 45.0;
const SPEED_DPS: f64 = 30.0;
const SEEDS: u64 = 8;
/// One measured sample per step.
const STEP_S: f64 = 0.001;
const RUN_S: f64 = 4.0;
/// The hold is judged over the last this long of a run.
const WINDOW_S: f64 = 1.0;
/// Noise on the measured q current, A (the simulator's reports').
const CURRENT_NOISE_A: f64 = 0.004;
/// The daemon's default contact threshold: this share of the hold setting.
const THRESHOLD_SHARE: f64 = 0.3;
const CONFIRM_S: f64 = 0.01;
const SLOWED_SHARE: f64 = 0.85;
const BRAKE_SHARE: f64 = 0.1;
const BRAKE_S: f64 = 0.1;
/// Cruising (learning the free-air current): within this share of the speed.
const CRUISE_SHARE: f64 = 0.1;
const BOUNDS: (f64, f64) = (-255.0, 255.0);

/// How the finger is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Position mode with MAX_CUR at the hold setting and the contact brake.
    Position,
    /// Current mode with the hold setting as the reference.
    Current,
}

/// One grasp of one finger.
#[derive(Debug, Clone, Copy, Default)]
struct Run {
    approach_dps: f64,
    contact_ms: f64,
    force_over_pct: f64,
    measured_over_pct: f64,
    force_error_pct: f64,
    measured_error_pct: f64,
}

/// Mean and worst of each measure over a case's runs.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Row {
    pub mode: Mode,
    pub nm_per_deg: f64,
    /// (mean, max) of: speed at contact, °/s; first touch, ms; peak push
    /// over the set force, %; peak measured current over the setting, %;
    /// |mean push − set force|, %; |mean measured − setting|, %.
    pub approach_dps: (f64, f64),
    pub contact_ms: (f64, f64),
    pub force_over_pct: (f64, f64),
    pub measured_over_pct: (f64, f64),
    pub force_error_pct: (f64, f64),
    pub measured_error_pct: (f64, f64),
}

/// The force the hold setting makes at rest (the resting current makes
/// none), as the q current that balances the object's push.
fn set_force_a() -> f64 {
    HOLD_A - HOLD_CURRENT_A
}

fn params() -> Params {
    let mut p = Params::factory(BaudLevel::B500000);
    if let Ok(raw) = current_limit_to_raw(HOLD_A) {
        p.set_raw(index::MAX_CUR, raw);
    }
    p
}

/// The position-mode contact detector and brake, as the daemon runs them.
#[derive(Debug, Default)]
struct Brake {
    learnt: (f64, u32),
    over_since: Option<f64>,
    braking_until: Option<f64>,
}

impl Brake {
    /// The speed limit for the next step, from the sample at `t`.
    fn vmax(&mut self, t: f64, measured: f64, vel: f64) -> f64 {
        if let Some(until) = self.braking_until {
            return if t < until {
                BRAKE_SHARE * SPEED_DPS
            } else {
                SPEED_DPS
            };
        }
        if (vel - SPEED_DPS).abs() < CRUISE_SHARE * SPEED_DPS && self.over_since.is_none() {
            self.learnt.0 += measured;
            self.learnt.1 += 1;
        }
        if self.learnt.1 >= 50 {
            let base = self.learnt.0 / f64::from(self.learnt.1);
            if measured - base >= THRESHOLD_SHARE * HOLD_A {
                let since = *self.over_since.get_or_insert(t);
                if t - since >= CONFIRM_S || vel < SLOWED_SHARE * SPEED_DPS {
                    self.braking_until = Some(t + BRAKE_S);
                    return BRAKE_SHARE * SPEED_DPS;
                }
            } else {
                self.over_since = None;
            }
        }
        SPEED_DPS
    }
}

/// One finger closing on an object at `at` of stiffness `k`.
fn run(mode: Mode, at: f64, k: f64, seed: u64) -> Run {
    let p = params();
    let mut rng = Rng::new(seed);
    let mut j = Joint {
        object: Some(Object::new(at, k)),
        ..Joint::default()
    };
    let mut brake = Brake::default();
    let set = set_force_a();
    let steps = (RUN_S / STEP_S).round() as usize;
    let window_from = ((RUN_S - WINDOW_S) / STEP_S).round() as usize;
    let (mut contact, mut peak_push, mut peak_measured) = (None, 0.0f64, 0.0f64);
    let (mut push_sum, mut measured_sum, mut n) = (0.0, 0.0, 0u32);
    let mut vmax = SPEED_DPS;
    for i in 0..steps {
        let drive = match mode {
            Mode::Position => Drive::Position {
                target: CLOSE_TO_DEG,
                vmax,
            },
            Mode::Current => Drive::Current { amps: HOLD_A },
        };
        let before = j.vel;
        j.advance(STEP_S, drive, &p, BOUNDS);
        let t = (i + 1) as f64 * STEP_S;
        let push = j.object.map_or(0.0, |o| o.push_a(j.pos).abs());
        let measured = j.q_loop.amps + rng.gauss(CURRENT_NOISE_A);
        if push > 0.0 && contact.is_none() {
            contact = Some((t, before));
        }
        if mode == Mode::Position {
            vmax = brake.vmax(t, measured, j.vel);
        }
        peak_push = peak_push.max(push);
        peak_measured = peak_measured.max(measured.abs());
        if i >= window_from {
            push_sum += push;
            measured_sum += measured.abs();
            n += 1;
        }
    }
    let (contact_s, approach) = contact.unwrap_or((f64::NAN, f64::NAN));
    let n = f64::from(n.max(1));
    Run {
        approach_dps: approach,
        contact_ms: contact_s * 1000.0,
        force_over_pct: (peak_push / set - 1.0) * 100.0,
        measured_over_pct: (peak_measured / HOLD_A - 1.0) * 100.0,
        force_error_pct: (push_sum / n / set - 1.0).abs() * 100.0,
        measured_error_pct: (measured_sum / n / HOLD_A - 1.0).abs() * 100.0,
    }
}

fn mean_max(runs: &[Run], f: impl Fn(&Run) -> f64) -> (f64, f64) {
    let v: Vec<f64> = runs.iter().map(f).collect();
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (mean, v.iter().copied().fold(f64::NEG_INFINITY, f64::max))
}

/// Every mode on every object, `seeds` noise seeds each.
pub(crate) fn compare_with(seeds: u64) -> Vec<Row> {
    let mut rows = Vec::new();
    for mode in [Mode::Position, Mode::Current] {
        for k in STIFFNESS {
            let runs: Vec<Run> = OBJECTS_DEG
                .iter()
                .flat_map(|&at| (1..=seeds).map(move |s| run(mode, at, k, s)))
                .collect();
            rows.push(Row {
                mode,
                nm_per_deg: k,
                approach_dps: mean_max(&runs, |r| r.approach_dps),
                contact_ms: mean_max(&runs, |r| r.contact_ms),
                force_over_pct: mean_max(&runs, |r| r.force_over_pct),
                measured_over_pct: mean_max(&runs, |r| r.measured_over_pct),
                force_error_pct: mean_max(&runs, |r| r.force_error_pct),
                measured_error_pct: mean_max(&runs, |r| r.measured_error_pct),
            });
        }
    }
    rows
}

/// The comparison as the bench prints it.
pub(crate) fn report() -> String {
    let mut out = format!(
        "grasp modes (simulated joint physics, rev 2.0.8, no daemon; hold {HOLD_A} A, \
         objects at 10/15/20 deg, {SEEDS} noise seeds each; mean / max):\n\
         mode                  k N·m/deg  approach deg/s  contact ms     force over %   measured over %  force err %  measured err %\n"
    );
    for r in compare_with(SEEDS) {
        let mode = match r.mode {
            Mode::Position => "position, MAX_CUR",
            Mode::Current => "current, cur_ref",
        };
        let f = |(a, b): (f64, f64)| format!("{a:6.1} / {b:6.1}");
        out.push_str(&format!(
            "{mode:<21} {:<9} {:<15} {:<14} {:<14} {:<16} {:<12} {}\n",
            r.nm_per_deg,
            f(r.approach_dps),
            f(r.contact_ms),
            f(r.force_over_pct),
            f(r.measured_over_pct),
            f(r.force_error_pct),
            f(r.measured_error_pct),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_modes_grasp_every_object_with_finite_numbers() {
        let rows = compare_with(1);
        assert_eq!(rows.len(), 4);
        for r in &rows {
            for (a, b) in [
                r.approach_dps,
                r.contact_ms,
                r.force_over_pct,
                r.measured_over_pct,
                r.force_error_pct,
                r.measured_error_pct,
            ] {
                assert!(a.is_finite() && b.is_finite(), "{r:?}");
            }
            assert!(r.approach_dps.0 > 0.0 && r.contact_ms.0 > 0.0, "{r:?}");
        }
        // A current drive free-runs far faster than the position closing.
        let approach = |m| {
            rows.iter()
                .find(|r| r.mode == m)
                .map_or(0.0, |r| r.approach_dps.0)
        };
        assert!(approach(Mode::Current) > 2.0 * approach(Mode::Position));
        assert!(report().lines().count() == 6);
    }
}
