//! A compliant object in a finger's way (something it grasps): from the
//! angle where contact starts, it pushes back with a torque proportional to
//! how far the finger presses in (`nm_per_deg`), which the motor must
//! answer with q-axis current. A finger under a current cap presses in only
//! as far as the cap pays for; a lower cap (a smaller limit, protection)
//! lets the object push it back out.
//!
//! SPEC gives no torque constant; the model's is [`OUTPUT_NM_PER_A`]: the
//! output torque one ampere of q current makes after the gearbox.
//!
//! Modelling choice: resting against an object in balance is not a stall
//! (no err 8): the joint is not held by something rigid it keeps pushing
//! into, and a hand must be able to hold.

use super::motor::HOLD_CURRENT_A;

/// Output torque per ampere of q-axis current, N·m/A (model constant: a
/// small BLDC's ≈ 3.5 mN·m/A through the 568.81:1 gearbox at ≈ 50 %).
pub const OUTPUT_NM_PER_A: f64 = 1.0;
/// Closer than this to the contact angle, the side is learnt from motion.
const SIDE_DEG: f64 = 1e-6;

/// An elastic object at a joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Object {
    /// Physical angle where contact starts, °.
    pub at: f64,
    /// Stiffness, N·m per degree pressed in.
    pub nm_per_deg: f64,
    /// Which side of `at` the joint is free on (+1: above); learnt from
    /// where the joint is when it first moves, or its first motion's way.
    side: Option<f64>,
}

impl Object {
    pub(crate) fn new(at: f64, nm_per_deg: f64) -> Self {
        Self {
            at,
            nm_per_deg: nm_per_deg.max(0.0),
            side: None,
        }
    }

    pub(crate) fn learn_side(&mut self, pos: f64, v_des: f64) {
        if self.side.is_none() {
            let d = pos - self.at;
            if d.abs() > SIDE_DEG {
                self.side = Some(d.signum());
            } else if v_des != 0.0 {
                self.side = Some(-v_des.signum());
            }
        }
    }

    /// The side of `at` the joint is free on (+1: above), once known.
    pub(crate) fn side(&self) -> Option<f64> {
        self.side
    }

    /// How far the joint at `pos` presses in, ° (0 when free of it).
    pub(crate) fn depth(&self, pos: f64) -> f64 {
        self.side.map_or(0.0, |s| ((self.at - pos) * s).max(0.0))
    }

    /// The object's push on the joint at `pos`, as the q current that
    /// balances it, signed the way it pushes (out of the object).
    pub(crate) fn push_a(&self, pos: f64) -> f64 {
        let side = self.side.unwrap_or(0.0);
        side * self.nm_per_deg * self.depth(pos) / OUTPUT_NM_PER_A
    }

    /// Where a joint going to `next` (driven at `v_des`, with `cap` amps to
    /// push with) ends up: no deeper than the cap pays for, holding current
    /// included.
    pub(crate) fn limit(&mut self, pos: f64, next: f64, v_des: f64, cap: f64) -> f64 {
        self.learn_side(pos, v_des);
        let Some(side) = self.side else {
            return next;
        };
        let max_depth = if self.nm_per_deg > 0.0 {
            (cap - HOLD_CURRENT_A).max(0.0) * OUTPUT_NM_PER_A / self.nm_per_deg
        } else {
            f64::INFINITY
        };
        if self.depth(next) > max_depth {
            self.at - side * max_depth
        } else {
            next
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pushes_back_in_proportion_to_depth_once_the_side_is_known() {
        let mut o = Object::new(10.0, 0.05);
        assert_eq!(o.push_a(12.0), 0.0, "side not known yet: no push");
        assert_eq!(o.limit(0.0, 1.0, 20.0, 1.0), 1.0, "free below it");
        assert_eq!(o.depth(5.0), 0.0);
        assert!((o.depth(12.0) - 2.0).abs() < 1e-12);
        // 0.05 N·m/° × 2° = 0.1 N·m, pushing the joint back down.
        assert!((o.push_a(12.0) + 0.1 / OUTPUT_NM_PER_A).abs() < 1e-12);
    }

    #[test]
    fn a_joint_presses_in_only_as_far_as_its_cap_pays_for() {
        let mut o = Object::new(10.0, 0.1);
        o.limit(0.0, 0.0, 1.0, 1.0);
        let cap = 0.23;
        let deepest = (cap - HOLD_CURRENT_A) * OUTPUT_NM_PER_A / 0.1;
        let at = o.limit(10.0, 30.0, 40.0, cap);
        assert!((at - (10.0 + deepest)).abs() < 1e-9, "{at}");
        assert_eq!(
            o.limit(10.0, 30.0, 40.0, 0.0),
            10.0,
            "no current: pushed out"
        );
    }
}

#[cfg(test)]
mod joint_tests {
    use super::*;
    use crate::protocol::params::index;
    use crate::protocol::units::current_limit_to_raw;
    use crate::protocol::BaudLevel;
    use crate::sim::params::Params;
    use crate::sim::physics::{Drive, Joint};

    const BOUNDS: (f64, f64) = (-255.0, 255.0);
    const CLOSE: Drive = Drive::Position {
        target: 60.0,
        vmax: 30.0,
    };

    fn capped(amps: f64) -> Params {
        let mut p = Params::factory(BaudLevel::B500000);
        p.set_raw(index::MAX_CUR, current_limit_to_raw(amps).unwrap());
        p
    }

    fn on(at: f64, nm_per_deg: f64) -> Joint {
        Joint {
            object: Some(Object::new(at, nm_per_deg)),
            ..Joint::default()
        }
    }

    #[test]
    fn the_current_rises_as_the_finger_presses_in_and_holds_at_its_cap() {
        let p = capped(0.2);
        let mut j = on(20.0, 0.01);
        j.advance(0.6, CLOSE, &p, BOUNDS);
        assert!(
            j.pos < 20.0 && j.current < 0.1,
            "free: {} {}",
            j.pos,
            j.current
        );
        let mut last = j.current;
        for _ in 0..10 {
            j.advance(0.05, CLOSE, &p, BOUNDS);
            assert!(
                j.current >= last - 0.005,
                "rising: {last} then {}",
                j.current
            );
            last = j.current;
        }
        j.advance(2.0, CLOSE, &p, BOUNDS);
        let deepest = (0.2 - HOLD_CURRENT_A) * OUTPUT_NM_PER_A / 0.01;
        assert!((j.pos - (20.0 + deepest)).abs() < 0.2, "pos {}", j.pos);
        assert!(
            (j.current - 0.2).abs() < 0.005,
            "holds at its cap: {}",
            j.current
        );
        assert!(!j.blocked && j.blocked_s == 0.0, "no stall");
    }

    #[test]
    fn a_stiffer_object_stops_the_finger_sooner_at_the_same_current() {
        let p = capped(0.2);
        let (mut soft, mut stiff) = (on(20.0, 0.01), on(20.0, 0.1));
        soft.advance(3.0, CLOSE, &p, BOUNDS);
        stiff.advance(3.0, CLOSE, &p, BOUNDS);
        assert!(stiff.pos < soft.pos - 10.0, "{} vs {}", stiff.pos, soft.pos);
        assert!((stiff.current - soft.current).abs() < 0.01);
    }

    #[test]
    fn pulled_away_the_finger_closes_on_and_its_current_drops() {
        let p = capped(0.2);
        let mut j = on(20.0, 0.05);
        j.advance(2.0, CLOSE, &p, BOUNDS);
        assert!(j.current > 0.19);
        j.object = None;
        j.advance(0.3, CLOSE, &p, BOUNDS);
        assert!(j.pos > 25.0 && j.current < 0.12, "{} {}", j.pos, j.current);
    }

    #[test]
    fn released_the_object_pushes_it_out_and_a_current_drive_balances_it() {
        let p = capped(0.5);
        let mut j = on(20.0, 0.05);
        j.advance(2.0, CLOSE, &p, BOUNDS);
        assert!(j.pos > 20.5);
        j.advance(0.01, Drive::Off, &p, BOUNDS);
        assert!(j.pos <= 20.0 + 1e-9, "pushed out: {}", j.pos);
        let mut c = on(20.0, 0.05);
        c.advance(3.0, Drive::Current { amps: 0.25 }, &p, BOUNDS);
        // It rests where the push leaves no more than the hold current.
        let push = -c.object.unwrap().push_a(c.pos);
        assert!(
            c.pos > 20.0 && (0.25 - push) <= HOLD_CURRENT_A + 0.01,
            "{} {push}",
            c.pos
        );
        assert!((c.current - 0.25).abs() < 1e-9);
    }
}
