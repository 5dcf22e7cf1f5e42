//! `JointState` messages from a bus's replies as they cross the wire (the
//! frame tap): one per poll round, when every online joint has answered a
//! status poll (INFO_01 or INFO_02) since the last message, so the message
//! rate is the bus's telemetry rate per joint. Angles and speeds go through
//! each joint's calibration (the same frame as the REST API), in SI units:
//! rad, rad/s at the output shaft; effort is the q-axis current in A. The
//! stamp is the wire time of the newest reply in the message.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use crate::bus::handle::{DeviceState, LoggedFrame};
use crate::bus::BusSnapshot;
use crate::hands::Calibration;
use crate::protocol::{units, Frame, Message, ReplyBody};

use crate::rosmsg::JointState;

/// A joint's name and calibration, as the daemon's config and state give them.
pub type Labeler = Arc<dyn Fn(&str, u8) -> (String, Calibration) + Send + Sync>;

/// What the latest replies of one joint said.
#[derive(Debug, Clone, Copy, Default)]
struct Heard {
    angle: i16,
    /// From the latest INFO_02 (INFO_01 carries neither).
    speed: i16,
    q_cur: i16,
    at: Option<SystemTime>,
    /// A reply came since the last message.
    fresh: bool,
}

/// Whose joints a message carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Scope {
    /// Every online joint of one bus, by id.
    Bus(String),
    /// A named hand's joints (bus, id), in its order, possibly on several buses.
    Hand {
        name: String,
        joints: Vec<(String, u8)>,
    },
}

/// Builds the messages of one bus or one hand.
pub struct JointStates {
    scope: Scope,
    labeler: Labeler,
    heard: BTreeMap<(String, u8), Heard>,
}

/// Names the scope; the labeler is a closure.
impl std::fmt::Debug for JointStates {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("JointStates")
            .field("scope", &self.scope)
            .finish_non_exhaustive()
    }
}

impl JointStates {
    /// Every joint of `bus`.
    pub fn new(bus: &str, labeler: Labeler) -> Self {
        Self::of(Scope::Bus(bus.to_owned()), labeler)
    }

    pub fn of(scope: Scope, labeler: Labeler) -> Self {
        Self {
            scope,
            labeler,
            heard: BTreeMap::new(),
        }
    }

    fn wants(&self, bus: &str, id: u8) -> bool {
        match &self.scope {
            Scope::Bus(b) => b == bus,
            Scope::Hand { joints, .. } => joints.iter().any(|(b, i)| b == bus && *i == id),
        }
    }

    /// Takes in a frame of `bus`: a status reply updates its joint.
    pub fn on_frame(&mut self, bus: &str, f: &LoggedFrame) {
        if f.tx {
            return;
        }
        let Ok(Message::Reply(reply)) =
            Frame::decode(&f.bytes).and_then(|fr| Message::from_frame(&fr))
        else {
            return;
        };
        if !self.wants(bus, reply.dev_id) {
            return;
        }
        let h = self
            .heard
            .entry((bus.to_owned(), reply.dev_id))
            .or_default();
        match reply.body() {
            ReplyBody::Info01(i) => h.angle = i.angle,
            ReplyBody::Info02(i) => {
                h.angle = i.angle;
                h.speed = i.speed;
                h.q_cur = i.q_cur;
            }
            _ => return,
        }
        h.at = Some(f.at);
        h.fresh = true;
    }

    /// The joints of the scope online now, in message order, with their
    /// state (`snapshots`: the latest of each bus concerned).
    fn online<'a>(&self, snapshots: &'a [&'a BusSnapshot]) -> Vec<(&'a str, &'a DeviceState)> {
        let find = |bus: &str| snapshots.iter().find(|s| s.name == bus);
        match &self.scope {
            Scope::Bus(bus) => find(bus)
                .map(|s| {
                    s.devices
                        .values()
                        .filter(|d| d.online)
                        .map(|d| (s.name.as_str(), d))
                        .collect()
                })
                .unwrap_or_default(),
            Scope::Hand { joints, .. } => joints
                .iter()
                .filter_map(|(bus, id)| {
                    let s = find(bus)?;
                    s.devices
                        .get(id)
                        .filter(|d| d.online)
                        .map(|d| (s.name.as_str(), d))
                })
                .collect(),
        }
    }

    /// A message when every online joint of the scope has answered since
    /// the last one; `None` until then.
    pub fn next(&mut self, snapshots: &[&BusSnapshot]) -> Option<JointState> {
        let online = self.online(snapshots);
        let fresh = |bus: &str, id: u8| {
            self.heard
                .get(&(bus.to_owned(), id))
                .is_some_and(|h| h.fresh)
        };
        if online.is_empty() || !online.iter().all(|(b, d)| fresh(b, d.dev_id)) {
            return None;
        }
        let frame_id = match &self.scope {
            Scope::Bus(bus) => bus.clone(),
            Scope::Hand { name, .. } => name.clone(),
        };
        let mut msg = JointState {
            frame_id,
            ..JointState::default()
        };
        let mut newest: Option<SystemTime> = None;
        for (bus, dev) in online {
            let Some(h) = self.heard.get_mut(&(bus.to_owned(), dev.dev_id)) else {
                continue;
            };
            let (name, cal) = (self.labeler)(bus, dev.dev_id);
            let rpm = units::speed_rpm(h.speed, dev.firmware_version());
            msg.name.push(name);
            msg.position
                .push(cal.to_joint(units::angle_deg(h.angle)).to_radians());
            msg.velocity
                .push((cal.sign() * units::output_deg_per_s(rpm)).to_radians());
            msg.effort.push(cal.sign() * units::current_a(h.q_cur));
            h.fresh = false;
            newest = newest.max(h.at);
        }
        msg.stamp_ns = newest.map_or(0, system_ns);
        Some(msg)
    }
}

/// A wall-clock time as Unix ns.
pub fn system_ns(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::bus::handle::DeviceState;
    use crate::protocol::{Info01, Info02, Reply};

    fn heard(body: ReplyBody, id: u8, ms: u64) -> LoggedFrame {
        LoggedFrame {
            at: UNIX_EPOCH + Duration::from_millis(ms),
            tx: false,
            bytes: Reply::new(id, body).encode(),
        }
    }

    fn snapshot(ids: &[u8]) -> BusSnapshot {
        let mut snap = BusSnapshot::new("l", "/dev/null", 500_000);
        for &dev_id in ids {
            let dev = DeviceState {
                dev_id,
                online: true,
                ..DeviceState::default()
            };
            snap.devices.insert(dev_id, dev);
        }
        snap
    }

    #[test]
    fn a_message_per_round_in_the_calibrated_frame_and_si_units() {
        let flipped = Calibration {
            offset_deg: 10.0,
            flip: true,
            ..Calibration::IDENTITY
        };
        let labeler: Labeler = Arc::new(move |bus: &str, id: u8| {
            let cal = if id == 2 {
                flipped
            } else {
                Calibration::IDENTITY
            };
            (format!("{bus}_{id}"), cal)
        });
        let mut js = JointStates::new("l", labeler);
        let snap = snapshot(&[1, 2]);
        let info2 = |angle_deg: f64, q: i16| {
            ReplyBody::Info02(Info02 {
                d_cur: 0,
                q_cur: q,
                speed: 0,
                angle: units::angle_to_raw(angle_deg).unwrap(),
            })
        };
        js.on_frame("l", &heard(info2(45.0, 1000), 1, 1000));
        assert_eq!(js.next(&[&snap]), None, "joint 2 has not answered yet");
        js.on_frame("l", &heard(info2(40.0, 1000), 2, 1002));
        let msg = js.next(&[&snap]).expect("a round");
        assert_eq!(msg.name, ["l_1", "l_2"]);
        assert!((msg.position[0] - 45f64.to_radians()).abs() < 1e-12);
        // Flipped about 10 degrees: device 40 reads -30.
        assert!((msg.position[1] - (-30f64).to_radians()).abs() < 1e-12);
        assert!(msg.effort[0] > 0.0 && (msg.effort[0] + msg.effort[1]).abs() < 1e-12);
        assert_eq!(msg.stamp_ns, 1_002_000_000, "the newest reply's wire time");
        assert_eq!(js.next(&[&snap]), None, "one message per round");
        // An INFO_01 counts as an answer and moves the angle.
        let info1 = ReplyBody::Info01(Info01 {
            angle: units::angle_to_raw(50.0).unwrap(),
            ..Info01::default()
        });
        js.on_frame("l", &heard(info1, 1, 1010));
        js.on_frame("l", &heard(info2(40.0, 0), 2, 1011));
        let next = js.next(&[&snap]).expect("the second round");
        assert!((next.position[0] - 50f64.to_radians()).abs() < 1e-12);
        // A host frame is not an answer.
        let mut tx = heard(info2(0.0, 0), 1, 1020);
        tx.tx = true;
        js.on_frame("l", &tx);
        js.on_frame("l", &heard(info2(40.0, 0), 2, 1021));
        assert_eq!(js.next(&[&snap]), None);
    }
}
