//! What one case measured over its runs and fingers (peaks and window sums
//! per finger), and its printout against the goals.

use std::time::Instant;

use super::setup::{FINGERS, HOLD_A, MAX_HOLD_ERROR_PCT, MAX_OVERSHOOT_PCT};
use crate::bus::BusHandle;
use crate::control::books::grasps::{FingerGrasp, FingerState};
use crate::protocol::units;
use crate::sim::physics::HOLD_CURRENT_A;
use crate::sim::SimHandle;

/// What one case (firmware, stiffness) measured, over its runs and fingers.
#[derive(Debug, Default)]
pub(super) struct Case {
    /// Call to contact, ms, per finger.
    pub(super) contact_ms: [Vec<f64>; 3],
    /// Peak measured |q current| over the hold setting, %.
    pub(super) measured_over_pct: Vec<f64>,
    /// Peak object push over the set force, %.
    pub(super) force_over_pct: Vec<f64>,
    /// Mean measured |q current| against the setting, %.
    pub(super) hold_error_pct: Vec<f64>,
    /// Mean object push against the set force, %.
    pub(super) force_error_pct: Vec<f64>,
    pub(super) missed: usize,
}

impl Case {
    /// One grasp's fingers as it ended, with their `traces`: the figures
    /// of each that holds, a miss for each that does not.
    pub(super) fn tally(&mut self, fingers: &[FingerGrasp], traces: &[Trace; 3]) {
        for (k, (f, t)) in fingers.iter().zip(traces).enumerate() {
            match (f.state, f.contact_after_ms) {
                (FingerState::Holding, Some(ms)) => {
                    self.contact_ms[k].push(ms);
                    self.measured_over_pct
                        .push(((t.peak_measured - HOLD_A) / HOLD_A * 100.0).max(0.0));
                    self.force_over_pct
                        .push(((t.peak_push - set_force_a()) / set_force_a() * 100.0).max(0.0));
                    let mean = |(sum, n): (f64, u32)| sum / f64::from(n.max(1));
                    self.hold_error_pct
                        .push((mean(t.measured) - HOLD_A).abs() / HOLD_A * 100.0);
                    self.force_error_pct
                        .push((mean(t.push) - set_force_a()).abs() / set_force_a() * 100.0);
                }
                (state, _) => {
                    println!(
                        "  missed: finger {} {state:?} ({}) peak measured {:.3} A, peak push {:.3} A",
                        f.joint,
                        f.reason.as_deref().unwrap_or("-"),
                        t.peak_measured,
                        t.peak_push
                    );
                    self.missed += 1;
                }
            }
        }
    }
}

/// The force the hold setting makes at rest, as the q current that
/// balances the object's push: the resting current makes none.
pub(super) fn set_force_a() -> f64 {
    HOLD_A - HOLD_CURRENT_A
}

/// Peaks and window sums of one grasp, per finger.
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Trace {
    pub(super) peak_measured: f64,
    pub(super) peak_push: f64,
    pub(super) measured: (f64, u32),
    pub(super) push: (f64, u32),
    /// The last INFO_02 seen (each report counts once).
    pub(super) last_report: Option<Instant>,
}

/// One look at every finger: the daemon's latest INFO_02 (each report
/// once) and the simulator's object push; summed too when `in_window`.
pub(super) fn sample(sim: &SimHandle, bus: &BusHandle, traces: &mut [Trace; 3], in_window: bool) {
    let snap = bus.snapshot();
    for (k, (id, _, _)) in FINGERS.iter().enumerate() {
        let t = &mut traces[k];
        let report = snap.devices.get(id).and_then(|d| d.info02.as_ref());
        if let Some((info, at)) = report.filter(|(_, at)| t.last_report != Some(*at)) {
            t.last_report = Some(*at);
            let q = units::current_a(info.q_cur).abs();
            t.peak_measured = t.peak_measured.max(q);
            if in_window {
                t.measured.0 += q;
                t.measured.1 += 1;
            }
        }
        if let Some(d) = sim.device(*id) {
            t.peak_push = t.peak_push.max(d.object_push_a);
            if in_window {
                t.push.0 += d.object_push_a;
                t.push.1 += 1;
            }
        }
    }
}

/// Prints one case; true when it met the goals (the overshoot goal on
/// both measures).
pub(super) fn print_case(firmware: &str, k: f64, speed_dps: f64, c: &Case, judged: bool) -> bool {
    let stat = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let max = v.iter().copied().fold(f64::NAN, f64::max);
        (mean, max)
    };
    let contact: Vec<String> = FINGERS
        .iter()
        .zip(&c.contact_ms)
        .map(|((_, name, at), ms)| {
            let (mean, max) = stat(ms);
            format!("{name} (object at {at} deg) {mean:.0} ms (max {max:.0})")
        })
        .collect();
    let (mo_mean, mo_max) = stat(&c.measured_over_pct);
    let (fo_mean, fo_max) = stat(&c.force_over_pct);
    let (he_mean, he_max) = stat(&c.hold_error_pct);
    let (fe_mean, fe_max) = stat(&c.force_error_pct);
    let passed = c.missed == 0
        && mo_max <= MAX_OVERSHOOT_PCT
        && fo_max <= MAX_OVERSHOOT_PCT
        && he_max <= MAX_HOLD_ERROR_PCT;
    println!(
        "grasp firmware {firmware} position mode, objects {k} N*m/deg at 10/15/20 deg, {speed_dps} deg/s, \
         hold {HOLD_A} A, {} finger-grasps{}\n  \
         call->contact: {}\n  \
         overshoot, peak measured q current over the setting: mean {mo_mean:.1} % (max {mo_max:.1}); \
         peak object push over the set force ({:.2} A): mean {fo_mean:.1} % (max {fo_max:.1}) (goal <= \
         {MAX_OVERSHOOT_PCT})\n  \
         hold error, mean measured q current: mean {he_mean:.1} % (max {he_max:.1}, goal <= \
         {MAX_HOLD_ERROR_PCT}); mean push against the set force: mean {fe_mean:.1} % (max {fe_max:.1})\n  \
         missed contacts {}",
        c.measured_over_pct.len(),
        match (judged, passed) {
            (false, _) => "  (not judged)",
            (true, true) => "",
            (true, false) => "  FAILED",
        },
        contact.join(", "),
        set_force_a(),
        c.missed,
    );
    passed
}
