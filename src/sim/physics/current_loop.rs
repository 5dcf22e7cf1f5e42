//! The drive's q-axis current loop: the current the winding carries (and
//! the drive measures) follows the capped reference the speed loop asks
//! for through a second-order response, so a step of the reference shows
//! in the measurement as a rise over a fraction of a millisecond with a
//! small overshoot.
//!
//! Model assumption (SPEC gives no current-loop dynamics; MAX_CUR, index
//! 18, is the cap on the *reference*): a natural frequency of 1 kHz and a
//! damping of 0.7, typical of a small FOC drive (a current loop closed at
//! a 10–20 kHz PWM rate, tuned to the "magnitude optimum", which puts its
//! damping near 1/√2: about 5 % overshoot on a step). The response is
//! solved exactly over each step (the reference held through it), so any
//! step length is stable.

use std::f64::consts::TAU;

/// Natural frequency of the current loop, rad/s (1 kHz).
pub(crate) const CURRENT_LOOP_RAD_S: f64 = TAU * 1000.0;
/// Damping ratio of the current loop.
pub(crate) const CURRENT_LOOP_DAMPING: f64 = 0.7;

/// The loop's state: the current it delivers and how fast that changes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct CurrentLoop {
    /// Delivered (and measured, before noise) q current, A.
    pub amps: f64,
    rate: f64,
}

impl CurrentLoop {
    /// Follows `reference` (held for `dt` seconds).
    pub(crate) fn advance(&mut self, reference: f64, dt: f64) {
        let w = CURRENT_LOOP_RAD_S;
        let sigma = CURRENT_LOOP_DAMPING * w;
        let wd = w * (1.0 - CURRENT_LOOP_DAMPING * CURRENT_LOOP_DAMPING).sqrt();
        let (e0, r0) = (self.amps - reference, self.rate);
        let decay = (-sigma * dt).exp();
        let (c, s) = ((wd * dt).cos(), (wd * dt).sin());
        let e = decay * (e0 * c + (r0 + sigma * e0) / wd * s);
        self.rate = decay * (r0 * c - (sigma * r0 + w * w * e0) / wd * s);
        self.amps = reference + e;
    }

    /// Power loss: nothing flows any more.
    pub(crate) fn reset(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_rises_within_a_millisecond_and_overshoots_a_few_percent() {
        let mut l = CurrentLoop::default();
        let (mut peak, mut t, dt) = (0.0f64, 0.0, 0.000_01);
        let mut rise = None;
        while t < 0.005 {
            l.advance(1.0, dt);
            t += dt;
            peak = peak.max(l.amps);
            if rise.is_none() && l.amps >= 0.9 {
                rise = Some(t);
            }
        }
        assert!(rise.is_some_and(|r| r < 0.001), "{rise:?}");
        assert!((0.03..0.07).contains(&(peak - 1.0)), "overshoot {peak}");
        assert!((l.amps - 1.0).abs() < 1e-6, "settled {}", l.amps);
    }

    #[test]
    fn the_exact_solution_does_not_depend_on_the_step_length() {
        let (mut a, mut b) = (CurrentLoop::default(), CurrentLoop::default());
        for _ in 0..20 {
            a.advance(0.5, 0.000_025);
        }
        b.advance(0.5, 0.000_5);
        b.advance(0.5, 0.0);
        assert!((a.amps - b.amps).abs() < 1e-9, "{} vs {}", a.amps, b.amps);
    }
}
