//! The teleoperation watchdog of one client, the same for every front-end
//! (a WebSocket connection, the ROS 2 bridge): armed with a hold timeout and
//! a policy, fed by every accepted batch of setpoints, fired when the stream
//! stops for longer than the hold timeout (or the client goes away while
//! armed). Pure: the caller says what time it is and does what firing asks
//! ([`fire_policy`]).

use std::collections::BTreeSet;
use std::time::Duration;

use tokio::time::Instant;

use super::joints::JointRef;
use super::state::Control;
use super::teleop::{apply_policy, WatchdogPolicy};

#[derive(Debug, Default)]
pub struct Watchdog {
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
    pub fn arm(&mut self, hold: Duration, policy: WatchdogPolicy, now: Instant) {
        self.armed = (!hold.is_zero()).then_some((hold, policy));
        self.last_fed = Some(now);
        self.fired = false;
        self.declared = true;
    }

    /// Whether a watchdog was ever set on this connection (a client's `0`
    /// disarms it for good; the config's default does not override that).
    pub fn declared(&self) -> bool {
        self.declared
    }

    pub fn feed(&mut self, joints: &[JointRef], now: Instant) {
        self.joints.extend(joints.iter().cloned());
        self.last_fed = Some(now);
        self.fired = false;
    }

    /// When the watchdog fires if nothing feeds it; `None` when it cannot fire.
    pub fn deadline(&self) -> Option<Instant> {
        let (hold, _) = self.armed?;
        if self.fired || self.joints.is_empty() {
            return None;
        }
        Some(self.last_fed? + hold)
    }

    /// Fires: the policy and the joints it applies to.
    pub fn fire(&mut self) -> Option<(WatchdogPolicy, Vec<JointRef>)> {
        let (_, policy) = self.armed?;
        if self.joints.is_empty() {
            return None;
        }
        self.fired = true;
        Some((policy, self.joints.iter().cloned().collect()))
    }

    pub fn is_armed(&self) -> bool {
        self.armed.is_some()
    }
}

/// What a fired watchdog does to `joints`, bus by bus: hold each where it
/// is, or disable them.
pub async fn fire_policy(control: &Control, policy: WatchdogPolicy, joints: &[JointRef]) {
    for bus in control.buses() {
        let ids: Vec<u8> = joints
            .iter()
            .filter(|j| j.bus == bus.name())
            .map(|j| j.id)
            .collect();
        if !ids.is_empty() {
            apply_policy(bus, ids, policy).await;
        }
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
