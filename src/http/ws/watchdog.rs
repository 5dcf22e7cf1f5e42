//! The teleoperation watchdog of one connection: armed by a `watchdog`
//! message, fed by every accepted `setpoints`, fired when the stream stops
//! for longer than the hold timeout or the socket closes while armed.

use std::collections::BTreeSet;
use std::time::Duration;

use tokio::time::Instant;

use crate::control::teleop::WatchdogPolicy;
use crate::control::JointRef;

#[derive(Debug, Default)]
pub(crate) struct Watchdog {
    /// `None`: disarmed.
    armed: Option<(Duration, WatchdogPolicy)>,
    last_fed: Option<Instant>,
    /// Every joint this connection has commanded.
    joints: BTreeSet<JointRef>,
    /// Set when fired, cleared by the next feed: fire once per stall.
    fired: bool,
    /// The client (or the config's default) has set it, armed or not.
    declared: bool,
}

impl Watchdog {
    pub(crate) fn arm(&mut self, hold: Duration, policy: WatchdogPolicy, now: Instant) {
        self.armed = (!hold.is_zero()).then_some((hold, policy));
        self.last_fed = Some(now);
        self.fired = false;
        self.declared = true;
    }

    /// Whether a watchdog was ever set on this connection (a client's `0`
    /// disarms it for good; the config's default does not override that).
    pub(crate) fn declared(&self) -> bool {
        self.declared
    }

    pub(crate) fn feed(&mut self, joints: &[JointRef], now: Instant) {
        self.joints.extend(joints.iter().cloned());
        self.last_fed = Some(now);
        self.fired = false;
    }

    /// When the watchdog fires if nothing feeds it; `None` when it cannot fire.
    pub(crate) fn deadline(&self) -> Option<Instant> {
        let (hold, _) = self.armed?;
        if self.fired || self.joints.is_empty() {
            return None;
        }
        Some(self.last_fed? + hold)
    }

    /// Fires: the policy and the joints it applies to.
    pub(crate) fn fire(&mut self) -> Option<(WatchdogPolicy, Vec<JointRef>)> {
        let (_, policy) = self.armed?;
        if self.joints.is_empty() {
            return None;
        }
        self.fired = true;
        Some((policy, self.joints.iter().cloned().collect()))
    }

    pub(crate) fn is_armed(&self) -> bool {
        self.armed.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(id: u8) -> JointRef {
        JointRef {
            bus: "b".into(),
            id,
        }
    }

    #[test]
    fn fires_once_per_stall_and_only_with_commanded_joints() {
        let t0 = Instant::now();
        let mut w = Watchdog::default();
        w.arm(Duration::from_millis(100), WatchdogPolicy::Disable, t0);
        assert_eq!(w.deadline(), None, "nothing commanded yet");
        w.feed(&[joint(1), joint(2)], t0);
        assert_eq!(w.deadline(), Some(t0 + Duration::from_millis(100)));
        let (policy, joints) = w.fire().unwrap();
        assert_eq!((policy, joints.len()), (WatchdogPolicy::Disable, 2));
        assert_eq!(w.deadline(), None, "fired once");
        w.feed(&[joint(3)], t0 + Duration::from_millis(500));
        assert_eq!(w.deadline(), Some(t0 + Duration::from_millis(600)));
        w.arm(Duration::ZERO, WatchdogPolicy::Hold, t0);
        assert!(!w.is_armed());
        assert_eq!(w.deadline(), None);
    }
}
