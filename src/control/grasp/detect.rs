//! What a closing or holding finger's samples mean, decided without I/O:
//! contact (the q current rose over the threshold above what the finger
//! draws moving freely, or it stalled), no contact (it reached its closing
//! limit), or, once holding, a lost object (the current fell back).
//!
//! Everything is measured along the closing direction: a finger slowing
//! down draws current *against* it, which never looks like contact. The
//! free-air current is learnt while the finger cruises at the asked speed
//! (not while it accelerates: the inertial current of the start would look
//! like a press), and no press counts before that, unless the finger could
//! not get going (it may start against the object). A finger that slowed
//! to a stall after it moved is in contact whatever its current says.
//!
//! The current is measured with noise (a few mA rms on a small drive):
//! a press counts once the rise has stayed over the threshold (at least
//! 0.02 A, five times the noise) for [`CONTACT_CONFIRM`] and at least
//! [`CONFIRM_SAMPLES`] reports in a row, so no single noisy report can
//! make one, unless the finger has also slowed under [`SLOWED_SHARE`] of
//! its speed (noise on the current does not slow it). The confirmation is
//! short because the finger's momentum presses on meanwhile: every 10 ms
//! of it is force overshoot on a stiff object.
//!
//! On contact the finger still carries the momentum of its closing: it
//! presses on into the object past where its current limit balances the
//! push, and the peak force overshoots the set one. Detected, the finger
//! brakes: its speed limit drops to [`CONTACT_SPEED_SHARE`] of the closing
//! speed for [`BRAKE`] (its position loop then takes current off while
//! the object pushes back), then the closing speed again, so a soft
//! object that is still being pressed in is not pressed slowly.

use std::time::Duration;

/// Before the free-air current is known, contact counts only after this
/// long (a finger that starts pressed never cruises).
pub(crate) const START_GRACE: Duration = Duration::from_millis(400);
/// The current must stay over the threshold this long ...
const CONTACT_CONFIRM: Duration = Duration::from_millis(10);
/// ... and in this many reports in a row (the bus publishes its snapshot,
/// with each joint's latest report, every 10 ms: two snapshots).
const CONFIRM_SAMPLES: u32 = 2;
/// A finger already slowed under this share of the asked speed needs no
/// second report: a press that also slows it is no noise.
const SLOWED_SHARE: f64 = 0.85;
/// After contact: the share of the closing speed the finger brakes to ...
pub(crate) const CONTACT_SPEED_SHARE: f64 = 0.1;
/// ... for this long.
pub(crate) const BRAKE: Duration = Duration::from_millis(100);
/// While braking and this long after, a current under the hold level is
/// the brake taking current off, not a lost object.
const BRAKE_SETTLE: Duration = Duration::from_millis(100);
/// Moving this slowly (share of the asked speed) for this long, after it
/// moved, is a stall: contact.
const STALLED_SHARE: f64 = 0.2;
const STALL_CONFIRM: Duration = Duration::from_millis(80);
/// It moved once it reached this share of the asked speed.
const MOVING_SHARE: f64 = 0.5;
/// Cruising: within this share of the asked speed.
const CRUISE_SHARE: f64 = 0.1;
/// The free-air current is the mean of this much cruising.
const LEARN: Duration = Duration::from_millis(50);
/// At the closing limit: this close to it, degrees ...
pub(crate) const LIMIT_TOLERANCE_DEG: f64 = 0.5;
/// ... and a stall closer than this to it is the position loop settling.
const STALL_MARGIN_DEG: f64 = 2.0;
/// Contact began where the rise over the free-air current was last under
/// this share of the threshold ...
const ONSET_SHARE: f64 = 0.25;
/// ... or this much, whichever is more (the current's noise), A.
const ONSET_MIN_A: f64 = 0.01;
/// A held object is lost once the current stays this long under the hold
/// current less the threshold.
const LOST_CONFIRM: Duration = Duration::from_millis(40);

/// The closing's settings, in device degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Settings {
    /// +1 closes towards higher device angles, −1 lower.
    pub dir: f64,
    pub limit_deg: f64,
    pub speed_dps: f64,
    pub threshold_a: f64,
    pub hold_a: f64,
}

/// One telemetry sample, device frame, signed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sample {
    /// Since the closing began.
    pub t: Duration,
    pub deg: f64,
    pub speed_dps: f64,
    pub current_a: f64,
}

/// What the samples say so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Verdict {
    Closing,
    /// In contact since the finger was at `deg` (device degrees).
    Contact {
        deg: f64,
        stalled: bool,
    },
    /// At the closing limit with nothing in the way.
    NoContact,
}

/// The contact detector of a closing finger.
#[derive(Debug, Clone)]
pub(crate) struct Closing {
    s: Settings,
    moved: bool,
    cruise_since: Option<Duration>,
    learning: (f64, u32),
    baseline: Option<f64>,
    over_since: Option<Duration>,
    /// Reports in a row over the threshold.
    over_n: u32,
    /// Where contact began: where the rise crossed the onset level,
    /// between the last report under it and the first over it.
    onset_deg: Option<f64>,
    /// The last report whose rise was under the onset level: (deg, rise).
    under: Option<(f64, f64)>,
    slow_since: Option<Duration>,
}

impl Closing {
    pub(crate) fn new(s: Settings) -> Self {
        Self {
            s,
            moved: false,
            cruise_since: None,
            learning: (0.0, 0),
            baseline: None,
            over_since: None,
            over_n: 0,
            onset_deg: None,
            under: None,
            slow_since: None,
        }
    }

    /// The free-air current learnt, A along the closing direction.
    pub(crate) fn baseline(&self) -> Option<f64> {
        self.baseline
    }

    pub(crate) fn sample(&mut self, x: Sample) -> Verdict {
        let s = self.s;
        let v = s.dir * x.speed_dps;
        let i = s.dir * x.current_a;
        let to_go = s.dir * (s.limit_deg - x.deg);
        self.moved |= v >= MOVING_SHARE * s.speed_dps;
        self.learn(x.t, v, i);
        if let Some(deg) = self.pressed(x, i, v) {
            return Verdict::Contact {
                deg,
                stalled: false,
            };
        }
        if self.stalled(x.t, v, to_go) {
            return Verdict::Contact {
                deg: x.deg,
                stalled: true,
            };
        }
        if to_go <= LIMIT_TOLERANCE_DEG && v.abs() < STALLED_SHARE * s.speed_dps {
            return Verdict::NoContact;
        }
        Verdict::Closing
    }

    fn learn(&mut self, t: Duration, v: f64, i: f64) {
        if self.baseline.is_some() {
            return;
        }
        if (v - self.s.speed_dps).abs() > CRUISE_SHARE * self.s.speed_dps {
            self.cruise_since = None;
            self.learning = (0.0, 0);
            return;
        }
        let since = *self.cruise_since.get_or_insert(t);
        self.learning.0 += i;
        self.learning.1 += 1;
        if t.saturating_sub(since) >= LEARN && self.learning.1 >= 3 {
            self.baseline = Some(self.learning.0 / f64::from(self.learning.1));
        }
    }

    /// The current over the threshold long enough: where the rise began.
    fn pressed(&mut self, x: Sample, i: f64, v: f64) -> Option<f64> {
        // Without a baseline, only a finger that never got going (it
        // started against the object) may count a press: one still
        // speeding up draws its inertial current.
        let armed = self.baseline.is_some() || (!self.moved && x.t >= START_GRACE);
        let base = self.baseline.unwrap_or(0.0).max(0.0);
        let rise = i - base;
        let onset = (ONSET_SHARE * self.s.threshold_a).max(ONSET_MIN_A);
        if rise < onset || self.onset_deg.is_none() {
            self.onset_deg = Some(x.deg);
            self.under = (rise < onset).then_some((x.deg, rise));
        } else if let Some((deg, under)) = self.under.take() {
            // The first report over it: the rise crossed the level between
            // the two. Reports far apart (a busy host) would otherwise put
            // the contact a whole report interval early.
            let share = (onset - under) / (rise - under);
            self.onset_deg = Some(deg + (x.deg - deg) * share);
        }
        if !armed || rise < self.s.threshold_a {
            self.over_since = None;
            self.over_n = 0;
            return None;
        }
        let since = *self.over_since.get_or_insert(x.t);
        self.over_n += 1;
        let confirmed = (x.t.saturating_sub(since) >= CONTACT_CONFIRM
            && self.over_n >= CONFIRM_SAMPLES)
            || v < SLOWED_SHARE * self.s.speed_dps;
        confirmed.then_some(self.onset_deg.unwrap_or(x.deg))
    }

    fn stalled(&mut self, t: Duration, v: f64, to_go: f64) -> bool {
        let slow = v < STALLED_SHARE * self.s.speed_dps;
        if !(self.moved && slow && to_go > LIMIT_TOLERANCE_DEG + STALL_MARGIN_DEG) {
            self.slow_since = None;
            return false;
        }
        let since = *self.slow_since.get_or_insert(t);
        t.saturating_sub(since) >= STALL_CONFIRM
    }
}

/// The lost-object detector of a holding finger, and when its brake ends.
#[derive(Debug, Clone)]
pub(crate) struct Holding {
    s: Settings,
    /// When contact was detected (since the closing began).
    contact_t: Duration,
    braking: bool,
    /// The current has come up to the hold level since contact: from then
    /// on a fall means the object is gone.
    settled: bool,
    low_since: Option<Duration>,
}

impl Holding {
    /// Holding since contact was detected at `contact_t`, braking.
    pub(crate) fn new(s: Settings, contact_t: Duration) -> Self {
        Self {
            s,
            contact_t,
            braking: true,
            settled: false,
            low_since: None,
        }
    }

    /// True once, at the first sample after the brake's time is up: the
    /// closing speed may come back.
    pub(crate) fn brake_ends(&mut self, x: Sample) -> bool {
        let over = self.braking && x.t >= self.contact_t + BRAKE;
        self.braking &= !over;
        over
    }

    /// True once the object is gone: the current fell (after it had come
    /// up to the hold level), or the finger got to its limit unopposed.
    pub(crate) fn lost(&mut self, x: Sample) -> bool {
        let s = self.s;
        let i = s.dir * x.current_a;
        let to_go = s.dir * (s.limit_deg - x.deg);
        self.settled |= i >= s.hold_a - s.threshold_a / 2.0;
        let braked = x.t < self.contact_t + BRAKE + BRAKE_SETTLE;
        let low = i < s.hold_a - s.threshold_a && !braked;
        if !low {
            self.low_since = None;
            return false;
        }
        if !self.settled {
            return to_go <= LIMIT_TOLERANCE_DEG;
        }
        let since = *self.low_since.get_or_insert(x.t);
        x.t.saturating_sub(since) >= LOST_CONFIRM
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Settings = Settings {
        dir: 1.0,
        limit_deg: 60.0,
        speed_dps: 30.0,
        threshold_a: 0.06,
        hold_a: 0.2,
    };
    const DT: Duration = Duration::from_millis(4);

    /// A finger starting at 0° with a first-order speed lag (tau), free
    /// current `0.03 + 0.0015 v + 0.00008 a`, and an object at `object`
    /// of `a_per_deg` (A per degree pressed in) under a cap of `hold_a`.
    fn run(s: Settings, tau: f64, object: Option<(f64, f64)>, sign: f64) -> (Verdict, f64) {
        run_noisy(s, tau, object, sign, &mut || 0.0)
    }

    /// [`run`] with `noise()` added to every reported current.
    fn run_noisy(
        s: Settings,
        tau: f64,
        object: Option<(f64, f64)>,
        sign: f64,
        noise: &mut dyn FnMut() -> f64,
    ) -> (Verdict, f64) {
        let (mut deg, mut v, mut t) = (0.0f64, 0.0f64, Duration::ZERO);
        let mut c = Closing::new(s);
        for _ in 0..5000 {
            let dt = DT.as_secs_f64();
            let goal = (40.0 * s.dir * (s.limit_deg - deg)).clamp(-s.speed_dps, s.speed_dps);
            let nv = v + (goal - v) * (dt / tau).min(1.0);
            let acc = (nv - v) / dt;
            v = nv;
            deg += s.dir * v * dt;
            let mut i = 0.03 + 0.0015 * v + 0.00008 * acc;
            if let Some((at, k)) = object {
                let depth = (s.dir * (deg - at)).max(0.0);
                let deepest = (s.hold_a - 0.03) / k;
                if depth > deepest {
                    deg = at + s.dir * deepest;
                    v = 0.0;
                }
                if depth > 0.0 {
                    i = 0.03 + k * depth.min(deepest) + 0.0015 * v;
                }
            }
            i = i.min(s.hold_a);
            t += DT;
            let x = Sample {
                t,
                deg,
                speed_dps: s.dir * v,
                current_a: s.dir * sign * i + noise(),
            };
            match c.sample(x) {
                Verdict::Closing => {}
                other => return (other, deg),
            }
        }
        (Verdict::Closing, deg)
    }

    #[test]
    fn free_air_ends_without_contact_whatever_the_smoothing_and_direction() {
        for tau in [0.004, 0.015, 0.06, 0.25] {
            for dir in [1.0, -1.0] {
                let s = Settings {
                    dir,
                    limit_deg: dir * 60.0,
                    ..S
                };
                let (v, deg) = run(s, tau, None, 1.0);
                assert_eq!(v, Verdict::NoContact, "tau {tau} dir {dir} at {deg}");
                assert!(
                    dir * (dir * 60.0 - deg) <= LIMIT_TOLERANCE_DEG,
                    "reached: {deg}"
                );
            }
        }
    }

    #[test]
    fn a_soft_and_a_stiff_object_are_felt_near_where_they_start() {
        for (k, slack) in [(0.01, 3.0), (0.1, 1.0)] {
            let (v, _) = run(S, 0.015, Some((25.0, k)), 1.0);
            let Verdict::Contact { deg, .. } = v else {
                panic!("k {k}: {v:?}");
            };
            assert!(deg > 25.0 && deg < 25.0 + slack, "k {k}: {deg}");
        }
    }

    #[test]
    fn an_object_where_the_finger_starts_is_contact_after_the_grace() {
        let (v, deg) = run(S, 0.015, Some((0.0, 0.1)), 1.0);
        assert!(matches!(v, Verdict::Contact { .. }), "{v:?}");
        assert!(deg < 2.0);
    }

    /// Normal noise of `sigma` from a fixed seed (xorshift, Box–Muller).
    fn gauss(seed: u64, sigma: f64) -> impl FnMut() -> f64 {
        let mut x = seed | 1;
        let mut unit = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        move || {
            let (u, v) = (1.0 - unit(), unit());
            sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    #[test]
    fn noise_on_the_current_makes_no_contact_in_free_air_even_at_the_lowest_threshold() {
        // 5 mA rms: a little over the simulator's 4 mA; the lowest
        // threshold is four times it.
        let s = Settings {
            threshold_a: 0.02,
            ..S
        };
        for seed in 1..=200 {
            let speed = 20.0 + 70.0 * f64::from(seed as u32 % 8) / 7.0;
            let s = Settings {
                speed_dps: speed,
                ..s
            };
            let (v, deg) = run_noisy(s, 0.015, None, 1.0, &mut gauss(seed, 0.005));
            assert_eq!(v, Verdict::NoContact, "seed {seed} at {deg}");
        }
    }

    /// A report at `ms` of a finger closing at 30 °/s from 0°, drawing `i` A.
    fn at(ms: u64, i: f64) -> Sample {
        Sample {
            t: Duration::from_millis(ms),
            deg: f64::from(ms as u32) * 0.03,
            speed_dps: 30.0,
            current_a: i,
        }
    }

    #[test]
    fn contact_begins_where_the_rise_crossed_the_onset_between_reports_far_apart() {
        let mut c = Closing::new(S);
        for ms in (0..100).step_by(4) {
            c.sample(at(ms, 0.075));
        }
        // 40 ms between reports (1.2 deg): under the onset level at 100 ms
        // (3.0 deg), far over it at 140 ms (4.2 deg). The rise of 0.125 A
        // crosses the onset level (0.015 A over the free-air 0.075 A) at
        // 0.12 of the way.
        assert_eq!(c.sample(at(100, 0.075)), Verdict::Closing);
        assert_eq!(c.sample(at(140, 0.2)), Verdict::Closing);
        let Verdict::Contact { deg, .. } = c.sample(at(150, 0.2)) else {
            panic!("contact");
        };
        assert!((deg - (3.0 + 1.2 * 0.12)).abs() < 1e-9, "{deg}");
    }

    #[test]
    fn noisy_objects_are_still_felt() {
        for seed in 1..=50 {
            let (v, _) = run_noisy(S, 0.015, Some((25.0, 0.1)), 1.0, &mut gauss(seed, 0.004));
            assert!(matches!(v, Verdict::Contact { .. }), "seed {seed}: {v:?}");
        }
    }

    #[test]
    fn one_report_over_the_threshold_is_no_contact_two_ten_ms_apart_are() {
        let mut c = Closing::new(S);
        for ms in (0..100).step_by(4) {
            assert_eq!(c.sample(at(ms, 0.075)), Verdict::Closing);
        }
        assert!(c.baseline().is_some());
        // One report over the threshold is never enough, however long ago
        // the rise began; two are, 10 ms apart.
        assert_eq!(c.sample(at(120, 0.2)), Verdict::Closing);
        assert_eq!(c.sample(at(124, 0.05)), Verdict::Closing, "back under");
        assert_eq!(c.sample(at(128, 0.2)), Verdict::Closing);
        assert_eq!(c.sample(at(134, 0.2)), Verdict::Closing, "6 ms");
        assert!(matches!(c.sample(at(138, 0.2)), Verdict::Contact { .. }));
        let mut c2 = Closing::new(S);
        for ms in (0..100).step_by(4) {
            c2.sample(at(ms, 0.075));
        }
        let slow = Sample {
            speed_dps: 24.0,
            ..at(120, 0.2)
        };
        assert!(
            matches!(c2.sample(slow), Verdict::Contact { .. }),
            "one report suffices when the finger slowed too"
        );
    }

    #[test]
    fn holding_brakes_once_and_a_dip_while_braking_is_no_loss() {
        let mut h = Holding::new(S, Duration::from_millis(500));
        let at = |ms: u64, i: f64| Sample {
            t: Duration::from_millis(ms),
            deg: 30.0,
            speed_dps: 0.0,
            current_a: i,
        };
        assert!(!h.brake_ends(at(550, 0.2)));
        assert!(!h.lost(at(550, 0.2)));
        assert!(!h.lost(at(560, 0.05)), "the brake takes current off");
        assert!(!h.lost(at(650, 0.05)));
        assert!(h.brake_ends(at(601, 0.05)));
        assert!(!h.brake_ends(at(610, 0.05)), "once");
        assert!(!h.lost(at(710, 0.05)), "the fall starts counting now");
        assert!(h.lost(at(760, 0.05)));
    }

    #[test]
    fn holding_loses_the_object_only_once_the_current_falls_after_settling() {
        let mut h = Holding::new(S, Duration::ZERO);
        let at = |ms: u64, deg: f64, i: f64| Sample {
            t: Duration::from_millis(ms) + BRAKE + BRAKE_SETTLE,
            deg,
            speed_dps: 0.0,
            current_a: i,
        };
        assert!(!h.lost(at(0, 30.0, 0.12)), "still pressing in");
        assert!(!h.lost(at(10, 31.0, 0.2)));
        assert!(!h.lost(at(20, 31.0, 0.1)), "not yet confirmed");
        assert!(!h.lost(at(30, 31.0, 0.19)), "back up: the fall was noise");
        assert!(!h.lost(at(40, 31.0, 0.08)));
        assert!(h.lost(at(90, 35.0, 0.08)));
        let mut early = Holding::new(S, Duration::ZERO);
        assert!(!early.lost(at(0, 40.0, 0.1)));
        assert!(early.lost(at(10, 59.8, 0.08)), "at the limit, unopposed");
    }
}
