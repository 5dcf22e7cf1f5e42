//! A finger pressing a compliant object, integrated as dynamics: the output's inertia (the rotor's, reflected
//! through the 568.81:1 gearbox: [`INERTIA_A_PER_DEG_S2`]) carries it on
//! into the object after contact until the object's push and the capped
//! motor current have stopped it; the object then pushes it back to the
//! static balance (push = cap − resting current). The peak push is the
//! force overshoot a grasp really makes.
//!
//! Model assumptions (SPEC gives the speed reference and MAX_CUR, not the
//! drive's loops):
//! - The drive tracks its smoothed speed reference (the LPF level's lag,
//!   as in free air) with a PI speed loop: a proportional current of
//!   `INERTIA × SPEED_LOOP_RAD_S` per °/s of speed error (a 20 Hz speed
//!   loop, typical of a small geared servo: far under its 1 kHz current
//!   loop, above the finger's mechanical modes) plus an integral term
//!   (time [`SPEED_LOOP_INTEGRAL_S`]) that learns the object's push. The
//!   resting current and friction are fed forward, so free of the object
//!   the joint follows the reference as the kinematic model does.
//! - The current reference is capped at MAX_CUR (the protection's cap
//!   while it holds), and the integral stops winding while it is capped.
//! - The resting current makes no torque (it is what the gearbox's static
//!   friction takes), in either direction; the gearbox's hysteresis (a
//!   finger that stays pressed in after an overshoot because the object
//!   cannot back-drive it) is not modelled: here it always settles back.
//! - Under a current drive (rev 2.0.8 current mode) there is no speed
//!   loop: the current reference is the asked current, capped the same
//!   way, and the finger arrives at the free-running speed that current
//!   holds against friction; the object's push alone decelerates it.
//! - The object is purely elastic (no damping of its own): only the
//!   joint's viscous friction damps the rebound, so overshoot is, if
//!   anything, overstated for foam or rubber.

use super::{Joint, FRICTION_A_PER_DEG_S, HOLD_CURRENT_A, INERTIA_A_PER_DEG_S2};
use crate::sim::object::{Object, OUTPUT_NM_PER_A};

/// Speed-loop bandwidth, rad/s (20 Hz).
pub(crate) const SPEED_LOOP_RAD_S: f64 = std::f64::consts::TAU * 20.0;
/// Speed-loop integral time, s.
pub(crate) const SPEED_LOOP_INTEGRAL_S: f64 = 0.05;
/// Largest share of an oscillation period one sub-step may take, rad.
const MAX_PHASE_PER_STEP: f64 = 0.05;
/// Sub-steps of one physics step at most (a very stiff object).
const MAX_SUBSTEPS: usize = 200;

/// What the drive asks for while pressing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum PressRef {
    /// A speed reference (position or speed drive) and its LPF lag, s.
    Speed { v_des: f64, tau: f64 },
    /// A fixed q-current reference, A (current drive).
    Current { amps: f64 },
}

impl PressRef {
    /// The way the drive pushes (its sign).
    fn dir(self) -> f64 {
        match self {
            Self::Speed { v_des, .. } => v_des,
            Self::Current { amps } => amps,
        }
    }
}

/// The speed loop's state while the joint presses an object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Press {
    /// The smoothed speed reference, °/s.
    pub v_ref: f64,
    /// The integral term: the load the loop has learnt, A.
    pub load_a: f64,
}

impl Joint {
    /// Whether this step of a position or speed drive is spent pressing
    /// the object (in it, or about to enter it at `v_next`).
    /// `v_des` gives the drive's way (its sign) while the side is unknown.
    pub(super) fn presses(&mut self, v_des: f64, v_next: f64, dt: f64) -> bool {
        let pos = self.pos;
        let Some(ob) = self.object.as_mut() else {
            return false;
        };
        ob.learn_side(pos, v_des);
        ob.depth(pos) > 0.0 || ob.depth(pos + v_next * dt) > 0.0
    }

    /// One step of the pressing dynamics (split into sub-steps short
    /// enough for the object's stiffness).
    pub(super) fn press_step(&mut self, dt: f64, r: PressRef, cap: f64, bounds: (f64, f64)) {
        let Some(ob) = self.object else { return };
        let mut press = self.press.unwrap_or(Press {
            v_ref: self.vel,
            load_a: 0.0,
        });
        let n = substeps(&ob, dt);
        let h = dt / n as f64;
        let v0 = self.vel;
        for _ in 0..n {
            self.press_substep(&mut press, h, r, cap, bounds);
        }
        self.acc = (self.vel - v0) / dt;
        self.press = Some(press);
    }

    fn press_substep(
        &mut self,
        press: &mut Press,
        h: f64,
        r: PressRef,
        cap: f64,
        bounds: (f64, f64),
    ) {
        let Some(ob) = self.object else { return };
        let current = match r {
            PressRef::Speed { v_des, tau } => {
                let along = -ob.side().unwrap_or(-v_des.signum());
                press.v_ref += (v_des - press.v_ref) * (h / tau).min(1.0);
                let err = press.v_ref - self.vel;
                let kp = INERTIA_A_PER_DEG_S2 * SPEED_LOOP_RAD_S;
                let demand = along * HOLD_CURRENT_A
                    + FRICTION_A_PER_DEG_S * self.vel
                    + kp * err
                    + press.load_a;
                let capped_along_err = (demand > cap && err > 0.0) || (demand < -cap && err < 0.0);
                if !capped_along_err {
                    press.load_a += kp * err * h / SPEED_LOOP_INTEGRAL_S;
                }
                demand.clamp(-cap, cap)
            }
            PressRef::Current { amps } => amps.clamp(-cap, cap),
        };
        let torque = current.signum() * (current.abs() - HOLD_CURRENT_A).max(0.0);
        let acc =
            (torque + ob.push_a(self.pos) - FRICTION_A_PER_DEG_S * self.vel) / INERTIA_A_PER_DEG_S2;
        self.vel += acc * h;
        self.move_by(self.vel * h, r.dir(), bounds);
        self.current = current;
        if self.blocked {
            self.blocked_s += h;
        } else {
            self.blocked_s = 0.0;
        }
    }
}

/// How many sub-steps keep one step of `dt` well inside the object's
/// oscillation (stiffness against the inertia).
fn substeps(ob: &Object, dt: f64) -> usize {
    let w = (ob.nm_per_deg / OUTPUT_NM_PER_A / INERTIA_A_PER_DEG_S2).sqrt();
    ((w * dt / MAX_PHASE_PER_STEP).ceil() as usize).clamp(1, MAX_SUBSTEPS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::params::index;
    use crate::protocol::units::current_limit_to_raw;
    use crate::protocol::BaudLevel;
    use crate::sim::params::Params;
    use crate::sim::physics::Drive;

    const BOUNDS: (f64, f64) = (-255.0, 255.0);
    const STEP: f64 = 0.001;

    fn capped(amps: f64) -> Params {
        let mut p = Params::factory(BaudLevel::B500000);
        p.set_raw(index::MAX_CUR, current_limit_to_raw(amps).unwrap());
        p
    }

    /// Closes at `speed` on an object at 20° of stiffness `k` under a
    /// 0.2 A cap for 3 s: the peak push, the push and current at the end.
    fn close_on(k: f64, speed: f64) -> (f64, f64, f64) {
        let p = capped(0.2);
        let mut j = Joint {
            object: Some(Object::new(20.0, k)),
            ..Joint::default()
        };
        let d = Drive::Position {
            target: 60.0,
            vmax: speed,
        };
        let mut peak = 0.0f64;
        for _ in 0..3000 {
            j.advance(STEP, d, &p, BOUNDS);
            peak = peak.max(-j.object.unwrap().push_a(j.pos));
        }
        (peak, -j.object.unwrap().push_a(j.pos), j.current)
    }

    #[test]
    fn momentum_carries_a_finger_past_the_balance_and_it_settles_back() {
        let balance = 0.2 - HOLD_CURRENT_A;
        let (peak, end, current) = close_on(0.1, 30.0);
        assert!(peak > balance * 1.1, "overshoot: peak {peak} vs {balance}");
        assert!(peak < balance * 1.5, "bounded: peak {peak}");
        assert!((end - balance).abs() < 0.003, "settled back: {end}");
        assert!(
            (current - 0.2).abs() < 1e-4,
            "holding at the cap: {current}"
        );
    }

    #[test]
    fn a_faster_finger_on_a_stiffer_object_overshoots_more() {
        let over = |k, v| close_on(k, v).0;
        assert!(over(0.1, 60.0) > over(0.1, 30.0) + 0.02);
        assert!(over(0.1, 30.0) > over(0.01, 30.0) + 0.01);
    }

    #[test]
    fn the_speed_loop_winds_up_to_the_cap_at_any_speed_limit() {
        for v in [10.0, 30.0] {
            let (_, end, current) = close_on(0.05, v);
            assert!((end - (0.2 - HOLD_CURRENT_A)).abs() < 0.003, "{v}: {end}");
            assert!((current - 0.2).abs() < 1e-4, "{v}: {current}");
        }
    }

    /// Drives 0.2 A (capped at 0.2 A) from rest at 0° into a stiff object
    /// at 20° for 3 s: the speed at contact, the peak push, the push and
    /// the delivered current at the end.
    fn current_into_stiff_object() -> (f64, f64, f64, f64) {
        let p = capped(0.2);
        let mut j = Joint {
            object: Some(Object::new(20.0, 0.1)),
            ..Joint::default()
        };
        let d = Drive::Current { amps: 0.2 };
        let (mut arrival, mut peak) = (None, 0.0f64);
        for _ in 0..3000 {
            let v = j.vel;
            j.advance(STEP, d, &p, BOUNDS);
            let push = -j.object.unwrap().push_a(j.pos);
            if push > 0.0 {
                arrival.get_or_insert(v);
            }
            peak = peak.max(push);
        }
        let end = -j.object.unwrap().push_a(j.pos);
        (arrival.unwrap_or(0.0), peak, end, j.q_loop.amps)
    }

    #[test]
    fn a_current_drive_arrives_at_its_free_speed_and_overshoots_the_balance() {
        let balance = 0.2 - HOLD_CURRENT_A;
        let (arrival, peak, end, delivered) = current_into_stiff_object();
        let free = balance / FRICTION_A_PER_DEG_S;
        assert!((arrival - free).abs() < 0.05 * free, "arrival {arrival}");
        assert!(peak > balance * 1.3, "overshoot: peak {peak} vs {balance}");
        assert!(peak < balance * 2.5, "bounded: peak {peak}");
        assert!((end - balance).abs() < 0.003, "settled back: {end}");
        assert!(
            (delivered - 0.2).abs() < 1e-4,
            "delivering the ask: {delivered}"
        );
    }

    #[test]
    fn a_very_stiff_object_stays_stable() {
        // Nearly rigid: the impact's force is brief and large, then it settles.
        let (peak, end, _) = close_on(50.0, 30.0);
        assert!(peak.is_finite() && peak < 5.0, "{peak}");
        assert!((end - (0.2 - HOLD_CURRENT_A)).abs() < 0.003, "{end}");
    }
}
