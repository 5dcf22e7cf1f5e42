//! Whether a joint that follows a path has stalled, judged on its
//! telemetry samples alone: each sample against where the path was at the
//! instant the sample was taken, so an old sample is no lag.
//!
//! A sample is off the path when it lies more than [`stall_bound_deg`]
//! from it. The joint has stalled when its samples stay off for
//! [`STALL_AFTER`] and over that span it moved towards the path less than
//! [`MOVED_SHARE`] of what the path travelled (and at least
//! [`MIN_MOVED_DEG`]): it is blocked. A joint that lags but moves (a late
//! owner or a stalled wire left it behind, or a high LPF level smooths its
//! speed) is not stalled: it catches up, or arrives after the path's end.
//! No new sample, no judgement: a joint that stops answering goes offline,
//! which ends its move another way.

use std::time::{Duration, Instant};

use super::ARRIVED_DEG;
use crate::motion::RunningMove;

/// Samples off the path this long, the joint barely moving, make a stall.
pub(crate) const STALL_AFTER: Duration = Duration::from_millis(300);
/// A joint that moved less than this share of the path's travel over the
/// span is blocked.
pub(crate) const MOVED_SHARE: f64 = 0.25;
/// ... and less than this, degrees (the path's travel is nil once it ended).
pub(crate) const MIN_MOVED_DEG: f64 = 0.5;

/// Off-path distance that counts towards a stall, degrees: a floor for
/// measurement and tracking lag, plus what the path covers in 50 ms at the
/// speed it asks (the position loop's and the speed filter's lag).
pub(crate) fn stall_bound_deg(path_speed_dps: f64) -> f64 {
    5.0 + path_speed_dps.abs() * 0.05
}

/// One telemetry sample of a joint: its angle (device degrees) and when
/// the owner took it in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sampled {
    pub deg: f64,
    pub at: Instant,
}

/// What the watch makes of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Verdict {
    Following,
    /// Off the path, not yet for long or still moving.
    Off,
    Stalled,
}

/// One follower's stall watch.
#[derive(Debug, Clone, Default)]
pub(crate) struct StallWatch {
    /// The newest sample judged.
    last: Option<Instant>,
    /// The first sample of the span the joint has been off its path.
    off_since: Option<Sampled>,
}

impl StallWatch {
    /// Judges `sample` (when new) against joint `joint` of `mv`; a sample
    /// older than the move, or already judged, changes nothing.
    pub(crate) fn look(&mut self, mv: &RunningMove, joint: usize, sample: Sampled) -> Verdict {
        let fresh = !self.last.is_some_and(|last| sample.at <= last) && sample.at >= mv.start();
        if !fresh {
            return if self.off_since.is_some() {
                Verdict::Off
            } else {
                Verdict::Following
            };
        }
        self.last = Some(sample.at);
        let t = mv.elapsed_at(sample.at);
        let ended = t >= mv.path.duration();
        let there = mv.path.sample(joint, t);
        let bound = if ended {
            ARRIVED_DEG.max(stall_bound_deg(0.0))
        } else {
            stall_bound_deg(there.velocity)
        };
        let gap = there.position - sample.deg;
        if gap.abs() <= bound {
            self.off_since = None;
            return Verdict::Following;
        }
        let Some(since) = self.off_since else {
            self.off_since = Some(sample);
            return Verdict::Off;
        };
        if sample.at.saturating_duration_since(since.at) < STALL_AFTER {
            return Verdict::Off;
        }
        let moved = (sample.deg - since.deg) * gap.signum();
        let path_then = mv.path.sample(joint, mv.elapsed_at(since.at)).position;
        let path_moved = (there.position - path_then).abs();
        if moved < (MOVED_SHARE * path_moved).max(MIN_MOVED_DEG) {
            return Verdict::Stalled;
        }
        // Moving: judged again over the next span.
        self.off_since = Some(sample);
        Verdict::Off
    }

    /// The joint is not running (it aligns, or stands disabled): no span.
    pub(crate) fn pause(&mut self) {
        self.off_since = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::{Method, Path};

    fn millis(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A linear path of joint 0 from 0° to 60° in 1 s (60 °/s), started at `t0`.
    fn sixty_in_a_second(t0: Instant) -> RunningMove {
        let path = Path::to(Method::Linear, vec![0.0], vec![60.0], millis(1000)).expect("a path");
        RunningMove::new(1, path, t0)
    }

    /// Looks at a sample every 10 ms from 0 to `until_ms`, the joint at
    /// `joint_deg(ms)`; the first stall's time, in ms.
    fn first_stall(until_ms: u64, joint_deg: impl Fn(u64) -> f64) -> Option<u64> {
        let t0 = Instant::now();
        let mv = sixty_in_a_second(t0);
        let mut w = StallWatch::default();
        (0..=until_ms).step_by(10).find(|&ms| {
            let s = Sampled {
                deg: joint_deg(ms),
                at: t0 + millis(ms),
            };
            w.look(&mv, 0, s) == Verdict::Stalled
        })
    }

    #[test]
    fn a_joint_left_behind_by_a_late_owner_moves_on_and_is_no_stall() {
        // 250 ms behind the path all along (15° at 60 °/s: past the 8°
        // bound), moving at the path's speed, then arriving.
        let lagging = |ms: u64| (ms.saturating_sub(250) as f64 * 0.06).min(60.0);
        assert_eq!(first_stall(2000, lagging), None);
    }

    #[test]
    fn a_blocked_joint_stalls_once_off_for_the_whole_span() {
        // Follows to 18° (300 ms), then stands there.
        let blocked = |ms: u64| (ms.min(300) as f64) * 0.06;
        let at = first_stall(2000, blocked).expect("a stall");
        // Off from the sample where the path is more than 8° on (at 440 ms).
        assert!((740..=760).contains(&at), "stalled at {at} ms");
    }

    #[test]
    fn a_joint_barely_creeping_stalls_too() {
        // Pressing a soft object: 18° then a tenth of the path's speed.
        let creeping = |ms: u64| ms.min(300) as f64 * 0.06 + ms.saturating_sub(300) as f64 * 0.006;
        assert!(first_stall(2000, creeping).is_some());
    }

    #[test]
    fn a_joint_short_of_the_goal_after_the_end_stalls() {
        let short = |ms: u64| (ms as f64 * 0.06).min(50.0);
        let at = first_stall(3000, short).expect("a stall");
        assert!(at > 1000, "stalled at {at} ms, before the path's end");
    }

    #[test]
    fn an_old_sample_seen_again_is_no_evidence() {
        let t0 = Instant::now();
        let mv = sixty_in_a_second(t0);
        let mut w = StallWatch::default();
        let old = Sampled {
            deg: 0.0,
            at: t0 + millis(10),
        };
        // The path runs on to its end; the owner still holds the sample
        // taken at 10 ms (the joint has not answered since).
        for _ in 0..100 {
            assert_ne!(w.look(&mv, 0, old), Verdict::Stalled);
        }
        // Sparse samples of a joint on its path are no stall either.
        for ms in (100..=1500).step_by(400) {
            let s = Sampled {
                deg: (ms as f64 * 0.06).min(60.0),
                at: t0 + millis(ms),
            };
            assert_eq!(w.look(&mv, 0, s), Verdict::Following, "at {ms} ms");
        }
    }

    #[test]
    fn a_sample_from_before_the_move_is_not_judged() {
        let t0 = Instant::now() + millis(500);
        let mv = sixty_in_a_second(t0);
        let mut w = StallWatch::default();
        let before = Sampled {
            deg: -40.0,
            at: t0 - millis(100),
        };
        assert_eq!(w.look(&mv, 0, before), Verdict::Following);
        let first = Sampled { deg: 0.0, at: t0 };
        assert_eq!(w.look(&mv, 0, first), Verdict::Following);
    }

    #[test]
    fn a_pause_forgets_the_span() {
        let t0 = Instant::now();
        let mv = sixty_in_a_second(t0);
        let mut w = StallWatch::default();
        let at = |ms: u64| Sampled {
            deg: 0.0,
            at: t0 + millis(ms),
        };
        assert_eq!(w.look(&mv, 0, at(200)), Verdict::Off);
        w.pause();
        assert_eq!(w.look(&mv, 0, at(450)), Verdict::Off, "a new span");
        assert_eq!(w.look(&mv, 0, at(760)), Verdict::Stalled);
    }
}
