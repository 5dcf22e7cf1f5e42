//! One joint's mechanics and electrics, integrated in small time steps:
//! output angle and speed under a position or speed drive shaped by the LPF
//! level, an optional obstacle or compliant object ([`super::object`]), the
//! q-axis current that results, the current
//! protection and burst of SPEC §4.3 (indices 18–23, 26, 27) and the winding
//! temperature.
//!
//! Free of an object the joint follows its drive kinematically (the speed
//! reaches the reference through the LPF level's lag, and the current is
//! what that motion costs); pressing an object, its momentum (and under a
//! position or speed drive the drive's speed loop, under a current drive
//! the fixed current reference) are integrated as dynamics ([`press`]). The current the physics computes is the capped
//! reference of the drive's current loop; what the winding carries and
//! the drive measures follows it ([`current_loop`]).
//!
//! All angles here are *physical* output degrees (before the device's zero
//! offset); speeds are output °/s.

pub(crate) mod current_loop;
pub(crate) mod press;

use crate::protocol::params::index;

use super::object::Object;
use super::params::Params;
use current_loop::CurrentLoop;
use press::{Press, PressRef};

/// Largest integration step; longer advances are split.
pub(crate) const MAX_STEP_S: f64 = 0.000_5;
/// Position loop gain: commanded speed per degree of error (1/s).
const POS_GAIN: f64 = 40.0;
/// Speed smoothing time constant per LPF level 0..=5 (higher = smoother).
const LPF_TAU_S: [f64; 6] = [0.004, 0.015, 0.03, 0.06, 0.12, 0.25];
/// How fast a released joint coasts to rest.
const COAST_TAU_S: f64 = 0.05;
pub(crate) use super::motor::HOLD_CURRENT_A;
/// Friction current per output °/s.
const FRICTION_A_PER_DEG_S: f64 = 0.0015;
/// Inertial current per output °/s²: the rotor's inertia reflected
/// through the 568.81:1 gearbox (≈ 4.6·10⁻³ kg·m² at the output under the
/// model's 1 N·m/A, a rotor of ≈ 0.14 g·cm², a small BLDC's).
const INERTIA_A_PER_DEG_S2: f64 = 0.000_08;
/// How fast the current climbs while pushing against an obstacle, A/s.
const BLOCKED_RAMP_A_PER_S: f64 = 4.0;
/// Closer than this to the obstacle counts as touching it, degrees.
const CONTACT_DEG: f64 = 1e-6;
/// Ambient temperature and heating (steady-state rise per A²), °C.
pub(crate) const AMBIENT_C: f64 = 29.0;
const HEAT_C_PER_A2: f64 = 40.0;
const THERMAL_TAU_S: f64 = 30.0;
const MS_PER_S: f64 = 1000.0;

/// What the controller asks of the motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Drive {
    /// Released: no torque, the joint coasts to rest.
    Off,
    /// Hold or move to `target` (physical °) at up to `vmax` °/s.
    Position { target: f64, vmax: f64 },
    /// Turn at `vel` °/s.
    Speed { vel: f64 },
    /// Drive `amps` of q-axis current (rev 2.0.8 current mode, capped like
    /// any current). A free joint settles where viscous friction takes what
    /// the hold (static) current leaves: `(|I| − hold) / friction` °/s.
    Current { amps: f64 },
}

/// Something the joint cannot move past.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Obstacle {
    /// Physical angle, °.
    pub at: f64,
    /// Which side the joint is on (+1: above `at`); learnt from the first
    /// motion when the obstacle is placed right where the joint is.
    pub side: Option<f64>,
}

impl Obstacle {
    pub(crate) fn at(at: f64) -> Self {
        Self { at, side: None }
    }

    /// Where a joint going from `pos` towards `next` (driven at `v_des`)
    /// ends up, and whether it pushes against this obstacle there.
    fn stop(&mut self, pos: f64, next: f64, v_des: f64) -> (f64, bool) {
        let at = self.at;
        let side = *self.side.get_or_insert_with(|| {
            let d = pos - at;
            if d.abs() > CONTACT_DEG {
                d.signum()
            } else {
                -v_des.signum()
            }
        });
        let next = if side != 0.0 && (next - at) * side < 0.0 {
            at
        } else {
            next
        };
        let touching = (next - at).abs() < CONTACT_DEG;
        if side == 0.0 {
            self.side = None;
        }
        (next, touching && v_des * side < 0.0)
    }
}

/// Current protection and burst state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Protection {
    pub active: bool,
    above_s: f64,
    below_s: f64,
    burst_left_s: f64,
    cool_left_s: f64,
}

impl Protection {
    pub(crate) fn bursting(&self) -> bool {
        self.burst_left_s > 0.0
    }
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Joint {
    pub pos: f64,
    pub vel: f64,
    pub acc: f64,
    /// q-axis current reference, A (signed, capped): what the speed loop
    /// asks of the current loop.
    pub current: f64,
    /// The current loop: the q current the winding carries and the drive
    /// measures.
    pub q_loop: CurrentLoop,
    /// The speed loop's state while pressing an object.
    pub press: Option<Press>,
    pub temp_c: f64,
    pub obstacle: Option<Obstacle>,
    /// A mechanical end stop (a finger's joint limit): an obstacle that no
    /// fault clears and no re-zero moves.
    pub hard_stop: Option<Obstacle>,
    /// Something elastic the joint closes on (a grasped object).
    pub object: Option<Object>,
    /// Pushing against the obstacle or the hard stop right now.
    pub blocked: bool,
    /// How long it has been pushing without a break, s.
    pub blocked_s: f64,
    pub prot: Protection,
}

impl Default for Joint {
    fn default() -> Self {
        Self {
            pos: 0.0,
            vel: 0.0,
            acc: 0.0,
            current: 0.0,
            q_loop: CurrentLoop::default(),
            press: None,
            temp_c: AMBIENT_C,
            obstacle: None,
            hard_stop: None,
            object: None,
            blocked: false,
            blocked_s: 0.0,
            prot: Protection::default(),
        }
    }
}

impl Joint {
    /// Advances by `dt` seconds (split into small steps).
    pub(crate) fn advance(&mut self, dt: f64, drive: Drive, p: &Params, bounds: (f64, f64)) {
        let mut left = dt;
        while left > 0.0 {
            let h = left.min(MAX_STEP_S);
            self.step(h, drive, p, bounds);
            left -= h;
        }
    }

    fn step(&mut self, dt: f64, drive: Drive, p: &Params, bounds: (f64, f64)) {
        let (v_des, tau) = match drive {
            Drive::Off => (0.0, COAST_TAU_S),
            Drive::Position { target, vmax } => (
                (POS_GAIN * (target - self.pos)).clamp(-vmax, vmax),
                lpf_tau(p),
            ),
            Drive::Speed { vel } => (vel, lpf_tau(p)),
            Drive::Current { amps } => {
                let push = self.object.map_or(0.0, |o| o.push_a(self.pos));
                (current_speed(amps, self.current_cap(p), push), lpf_tau(p))
            }
        };
        let vel = self.vel + (v_des - self.vel) * (dt / tau).min(1.0);
        let pressing = match drive {
            Drive::Off => None,
            Drive::Position { .. } | Drive::Speed { .. } => Some(PressRef::Speed { v_des, tau }),
            Drive::Current { amps } => Some(PressRef::Current { amps }),
        };
        let dir = match drive {
            Drive::Current { amps } => amps,
            _ => v_des,
        };
        if let Some(r) = pressing.filter(|_| self.presses(dir, vel, dt)) {
            let cap = self.current_cap(p);
            self.press_step(dt, r, cap, bounds);
        } else {
            self.press = None;
            self.acc = (vel - self.vel) / dt;
            self.vel = vel;
            self.move_by(vel * dt, v_des, bounds);
            self.press_object(drive, v_des, p);
            self.update_current(dt, drive, v_des, p);
        }
        self.q_loop.advance(self.current, dt);
        self.update_protection(dt, p);
        let heat = AMBIENT_C + HEAT_C_PER_A2 * self.current * self.current;
        self.temp_c += (heat - self.temp_c) * dt / THERMAL_TAU_S;
    }

    /// Moves, stopping at the travel bounds, the obstacle and the hard stop.
    fn move_by(&mut self, delta: f64, v_des: f64, (lo, hi): (f64, f64)) {
        let mut next = (self.pos + delta).clamp(lo, hi);
        if next != self.pos + delta {
            self.vel = 0.0;
        }
        self.blocked = false;
        let pos = self.pos;
        for ob in [self.obstacle.as_mut(), self.hard_stop.as_mut()]
            .into_iter()
            .flatten()
        {
            let (stopped, blocked) = ob.stop(pos, next, v_des);
            if stopped != next {
                next = stopped;
                self.vel = 0.0;
            }
            self.blocked |= blocked;
        }
        self.pos = next;
    }

    /// Released, the object pushes the joint out at once (driven, the
    /// joint presses it through [`press`]; a current drive is never
    /// limited here).
    fn press_object(&mut self, drive: Drive, v_des: f64, p: &Params) {
        let cap = match drive {
            Drive::Off => 0.0,
            Drive::Current { .. } => f64::INFINITY,
            _ => self.current_cap(p),
        };
        if let Some(ob) = self.object.as_mut() {
            let at = ob.limit(self.pos, self.pos, v_des, cap);
            if at != self.pos {
                self.pos = at;
                self.vel = 0.0;
            }
        }
    }

    fn update_current(&mut self, dt: f64, drive: Drive, v_des: f64, p: &Params) {
        let cap = self.current_cap(p);
        let demand = match drive {
            Drive::Off => 0.0,
            Drive::Current { amps } => {
                if self.blocked {
                    self.blocked_s += dt;
                }
                amps
            }
            _ if self.blocked => {
                self.blocked_s += dt;
                v_des.signum() * (self.current.abs() + BLOCKED_RAMP_A_PER_S * dt)
            }
            _ => {
                let sign = if self.vel != 0.0 {
                    self.vel.signum()
                } else {
                    1.0
                };
                sign * HOLD_CURRENT_A
                    + FRICTION_A_PER_DEG_S * self.vel
                    + INERTIA_A_PER_DEG_S2 * self.acc
            }
        };
        if !self.blocked {
            self.blocked_s = 0.0;
        }
        self.current = demand.clamp(-cap, cap);
    }

    /// Max current, or the protection limit while protection holds (but not
    /// during a burst).
    pub(crate) fn current_cap(&self, p: &Params) -> f64 {
        if self.prot.active && !self.prot.bursting() {
            p.physical(index::PROTECT_CUR_LIMIT)
        } else {
            p.physical(index::MAX_CUR)
        }
    }

    fn update_protection(&mut self, dt: f64, p: &Params) {
        let i = self.current.abs();
        let pr = &mut self.prot;
        pr.burst_left_s = (pr.burst_left_s - dt).max(0.0);
        pr.cool_left_s = (pr.cool_left_s - dt).max(0.0);
        if !pr.active {
            pr.above_s = if i > p.physical(index::PROTECT_CUR_LV1) {
                pr.above_s + dt
            } else {
                0.0
            };
            if pr.above_s * MS_PER_S >= p.physical(index::CUR_LV1_DELAY) && pr.above_s > 0.0 {
                pr.active = true;
                pr.below_s = 0.0;
            }
        } else {
            pr.below_s = if i < p.physical(index::RECV_CUR) {
                pr.below_s + dt
            } else {
                0.0
            };
            if pr.below_s * MS_PER_S >= p.physical(index::CUR_RECV_WIN) && pr.below_s > 0.0 {
                pr.active = false;
                pr.above_s = 0.0;
            }
        }
    }

    /// A new command while protection holds: a burst of full current for
    /// PLUS_TIME, then no other burst until COLD_TIME has passed.
    pub(crate) fn command_burst(&mut self, p: &Params) {
        let pr = &mut self.prot;
        if pr.active && pr.cool_left_s <= 0.0 && p.raw(index::PLUS_TIME) > 0 {
            pr.burst_left_s = p.physical(index::PLUS_TIME) / MS_PER_S;
            pr.cool_left_s = pr.burst_left_s + p.physical(index::COLD_TIME) / MS_PER_S;
        }
    }
}

/// The free-running output speed a q-axis current holds, °/s (the inverse
/// of the current a moving joint draws at steady speed), less what an
/// object's `push` (as a current) takes of it.
fn current_speed(amps: f64, cap: f64, push: f64) -> f64 {
    let net = amps.clamp(-cap, cap) + push;
    net.signum() * (net.abs() - HOLD_CURRENT_A).max(0.0) / FRICTION_A_PER_DEG_S
}

fn lpf_tau(p: &Params) -> f64 {
    LPF_TAU_S[usize::from(p.raw(index::POS_LPF_LV)).min(LPF_TAU_S.len() - 1)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::BaudLevel;

    const BOUNDS: (f64, f64) = (-255.0, 255.0);

    fn params() -> Params {
        Params::factory(BaudLevel::B500000)
    }

    #[test]
    fn position_drive_cruises_at_the_speed_limit_and_settles() {
        let mut j = Joint::default();
        let d = Drive::Position {
            target: 90.0,
            vmax: 100.0,
        };
        j.advance(0.5, d, &params(), BOUNDS);
        assert!((j.vel - 100.0).abs() < 1.0, "cruise {}", j.vel);
        assert!((j.pos - 50.0).abs() < 3.0, "pos {}", j.pos);
        j.advance(1.0, d, &params(), BOUNDS);
        assert!((j.pos - 90.0).abs() < 0.05, "settled {}", j.pos);
        assert!(j.current.abs() < 0.1);
    }

    #[test]
    fn current_drive_turns_a_free_joint_and_pushes_a_blocked_one() {
        let p = params();
        let mut j = Joint::default();
        let d = Drive::Current { amps: 0.3 };
        j.advance(0.5, d, &p, BOUNDS);
        let free = (0.3 - HOLD_CURRENT_A) / FRICTION_A_PER_DEG_S;
        assert!((j.vel - free).abs() < 1.0, "vel {}", j.vel);
        assert!((j.current - 0.3).abs() < 1e-9);
        let mut held = Joint::default();
        held.advance(0.5, Drive::Current { amps: 0.02 }, &p, BOUNDS);
        assert_eq!(held.pos, 0.0, "below the hold current nothing turns");
        let mut blocked = Joint {
            obstacle: Some(Obstacle::at(1.0)),
            ..Joint::default()
        };
        blocked.advance(0.5, d, &p, BOUNDS);
        assert_eq!(blocked.pos, 1.0);
        assert!(blocked.blocked && blocked.blocked_s > 0.1);
    }

    #[test]
    fn speed_drive_stops_at_the_travel_bound() {
        let mut j = Joint::default();
        j.advance(2.0, Drive::Speed { vel: 200.0 }, &params(), BOUNDS);
        assert_eq!(j.pos, 255.0);
    }

    #[test]
    fn obstacle_blocks_and_protection_engages_then_bursts() {
        let p = params();
        let mut j = Joint {
            obstacle: Some(Obstacle::at(10.0)),
            ..Joint::default()
        };
        let d = Drive::Position {
            target: 40.0,
            vmax: 100.0,
        };
        j.advance(0.5, d, &p, BOUNDS);
        assert_eq!(j.pos, 10.0);
        assert!(j.blocked);
        j.advance(1.0, d, &p, BOUNDS);
        assert!(j.prot.active, "current {}", j.current);
        assert!(j.current.abs() <= p.physical(index::PROTECT_CUR_LIMIT) + 1e-9);
        j.command_burst(&p);
        j.advance(0.05, d, &p, BOUNDS);
        assert!(j.current.abs() > p.physical(index::PROTECT_CUR_LIMIT));
        j.advance(0.1, d, &p, BOUNDS);
        assert!(j.current.abs() <= p.physical(index::PROTECT_CUR_LIMIT) + 1e-9);
        assert!(j.blocked_s > 1.0);
    }

    #[test]
    fn a_hard_stop_holds_beside_an_obstacle_and_only_one_way() {
        let p = params();
        let mut j = Joint {
            hard_stop: Some(Obstacle::at(-30.0)),
            obstacle: Some(Obstacle::at(20.0)),
            ..Joint::default()
        };
        j.advance(1.0, Drive::Speed { vel: -100.0 }, &p, BOUNDS);
        assert_eq!(j.pos, -30.0);
        assert!(j.blocked, "pushing into the hard stop");
        j.advance(0.3, Drive::Speed { vel: 100.0 }, &p, BOUNDS);
        assert!(!j.blocked && j.pos > -30.0, "leaving it is free");
        j.advance(1.0, Drive::Speed { vel: 100.0 }, &p, BOUNDS);
        assert_eq!(j.pos, 20.0, "the obstacle still blocks the other way");
        assert!(j.blocked);
    }

    #[test]
    fn moving_away_from_the_obstacle_is_free() {
        let mut j = Joint {
            obstacle: Some(Obstacle::at(5.0)),
            ..Joint::default()
        };
        j.advance(
            0.5,
            Drive::Position {
                target: -20.0,
                vmax: 100.0,
            },
            &params(),
            BOUNDS,
        );
        assert!((j.pos + 20.0).abs() < 0.5, "{}", j.pos);
        assert!(!j.blocked);
    }

    #[test]
    fn an_obstacle_placed_at_the_joint_blocks_the_first_motion() {
        let mut j = Joint {
            obstacle: Some(Obstacle::at(0.0)),
            ..Joint::default()
        };
        j.advance(
            0.2,
            Drive::Position {
                target: -20.0,
                vmax: 100.0,
            },
            &params(),
            BOUNDS,
        );
        assert_eq!(j.pos, 0.0);
        assert!(j.blocked);
    }
}
