//! One bus's taps turned into a recording's messages: every frame on the
//! wire, a joint state per poll round, every setpoint write, every event,
//! each as its channel's ([`Topic`], log time, bytes). The MCAP recorder
//! writes them to its file and the live Foxglove view logs them to its
//! clients: one encoder, so a file and the live view carry the same bytes
//! on the same topics.
//!
//! Taps are read without waiting (`try_recv`): the bus owner that sends
//! never waits for a reader, and a reader that falls too far behind loses
//! the oldest, counted in [`BusTap::lost`].

use std::sync::Arc;
use std::time::SystemTime;

use serde_json::json;
use tokio::sync::broadcast::error::TryRecvError;
use tokio::sync::{broadcast, watch};

use crate::bus::handle::{BusEvent, Commanded, LoggedFrame};
use crate::bus::{BusHandle, BusSnapshot};
use crate::protocol::frame_json::hex;
use crate::protocol::units;
use crate::protocol::CtrlMode;

use super::channels::Topic;
use super::joint_states::{system_ns, JointStates, Labeler};

/// What a bus tells: its snapshots (which joints are online), the frames
/// on its wire, its setpoint writes and its events.
pub struct Taps {
    pub snapshots: watch::Receiver<Arc<BusSnapshot>>,
    pub frames: broadcast::Receiver<LoggedFrame>,
    pub setpoints: broadcast::Receiver<Commanded>,
    pub events: broadcast::Receiver<BusEvent>,
}

/// Receivers only: nothing to show.
impl std::fmt::Debug for Taps {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Taps").finish_non_exhaustive()
    }
}

impl Taps {
    /// Every tap of `bus`, from now on.
    pub fn of(bus: &BusHandle) -> Self {
        Self {
            snapshots: bus.watch(),
            frames: bus.shared().frame_tap.subscribe(),
            setpoints: bus.shared().setpoints.subscribe(),
            events: bus.events(),
        }
    }
}

/// One bus's taps, and the joint states its frames make.
pub struct BusTap {
    bus: String,
    taps: Taps,
    labeler: Labeler,
    joint_states: JointStates,
    lost: u64,
}

/// Names the bus and what it lost.
impl std::fmt::Debug for BusTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BusTap")
            .field("bus", &self.bus)
            .field("lost", &self.lost)
            .finish_non_exhaustive()
    }
}

impl BusTap {
    /// The taps of `bus`, its joints named and calibrated by `labeler`.
    pub fn new(bus: &str, taps: Taps, labeler: Labeler) -> Self {
        Self {
            bus: bus.to_owned(),
            joint_states: JointStates::new(bus, labeler.clone()),
            taps,
            labeler,
            lost: 0,
        }
    }

    pub fn bus(&self) -> &str {
        &self.bus
    }

    /// Frames, setpoint writes and events this tap fell too far behind to see.
    pub fn lost(&self) -> u64 {
        self.lost
    }

    /// Everything the taps hold now, each message handed to `emit` as
    /// (topic, log time in Unix ns, bytes): the frames with the joint
    /// states they complete, then the setpoint writes, then the events. A
    /// message of a topic `wants` turns down is not encoded (nobody would
    /// read it); the frames still make the joint states. `emit`'s first
    /// error ends the drain.
    pub fn drain<E>(
        &mut self,
        wants: impl Fn(Topic) -> bool,
        mut emit: impl FnMut(Topic, u64, &[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
        // Which joints are online: a round is complete when each has answered.
        let snap = self.taps.snapshots.borrow_and_update().clone();
        self.drain_frames(&snap, &wants, &mut emit)?;
        self.drain_setpoints(&snap, &wants, &mut emit)?;
        self.drain_events(&wants, &mut emit)
    }

    fn drain_frames<E>(
        &mut self,
        snap: &BusSnapshot,
        wants: &impl Fn(Topic) -> bool,
        emit: &mut impl FnMut(Topic, u64, &[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
        while let Some(f) = next(&mut self.taps.frames, &mut self.lost) {
            if wants(Topic::Frames) {
                emit(Topic::Frames, system_ns(f.at), frame_json(&f).as_bytes())?;
            }
            self.joint_states.on_frame(&self.bus, &f);
            if let Some(state) = self.joint_states.next(&[snap]) {
                if wants(Topic::JointStates) {
                    emit(
                        Topic::JointStates,
                        state.stamp_ns,
                        state.to_cdr().as_slice(),
                    )?;
                }
            }
        }
        Ok(())
    }

    fn drain_setpoints<E>(
        &mut self,
        snap: &BusSnapshot,
        wants: &impl Fn(Topic) -> bool,
        emit: &mut impl FnMut(Topic, u64, &[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
        while let Some(c) = next(&mut self.taps.setpoints, &mut self.lost) {
            if wants(Topic::Setpoints) {
                let msg = setpoints_json(&self.bus, &c, snap, &self.labeler);
                emit(Topic::Setpoints, system_ns(c.at), msg.as_bytes())?;
            }
        }
        Ok(())
    }

    fn drain_events<E>(
        &mut self,
        wants: &impl Fn(Topic) -> bool,
        emit: &mut impl FnMut(Topic, u64, &[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
        while let Some(e) = next(&mut self.taps.events, &mut self.lost) {
            if wants(Topic::Events) {
                let text = serde_json::to_string(&e).unwrap_or_default();
                emit(Topic::Events, system_ns(SystemTime::now()), text.as_bytes())?;
            }
        }
        Ok(())
    }
}

/// The next item a tap holds, counting in `lost` what it dropped for
/// falling behind; `None` once it is empty (or closed).
fn next<T: Clone>(rx: &mut broadcast::Receiver<T>, lost: &mut u64) -> Option<T> {
    loop {
        match rx.try_recv() {
            Ok(item) => return Some(item),
            Err(TryRecvError::Lagged(n)) => *lost += n,
            Err(_) => return None,
        }
    }
}

/// A frame as the frames channel carries it (`schemas::frame`).
fn frame_json(f: &LoggedFrame) -> String {
    let dir = if f.tx { "tx" } else { "rx" };
    json!({"dir": dir, "wire_time_ns": system_ns(f.at), "hex": hex(&f.bytes)}).to_string()
}

/// A setpoint write as the setpoints channel carries it
/// (`schemas::setpoint`): who wrote it, its sequence number, its targets
/// in the joints' calibrated frame and raw.
fn setpoints_json(bus: &str, c: &Commanded, snap: &BusSnapshot, labeler: &Labeler) -> String {
    let targets: Vec<_> = c
        .targets
        .iter()
        .map(|(id, sp)| {
            let (_, cal) = labeler(bus, *id);
            json!({"id": id, "position_deg": cal.to_joint(units::angle_deg(sp.pos_ref)),
                "speed_dps": target_speed_dps(snap, *id, sp.spd_ref, cal.sign()),
                "pos_ref_raw": sp.pos_ref, "spd_ref_raw": sp.spd_ref})
        })
        .collect();
    let mut msg = serde_json::to_value(c.source).unwrap_or_else(|_| json!({}));
    msg["seq"] = json!(c.seq);
    msg["targets"] = json!(targets);
    msg.to_string()
}

/// A target's speed as the REST and WebSocket views give it: output °/s,
/// the limit in position mode, signed (in the joint's frame) in speed mode.
fn target_speed_dps(snap: &BusSnapshot, id: u8, spd_ref: i16, sign: f64) -> f64 {
    let dev = snap.devices.get(&id);
    let fw = dev.map(|d| d.firmware_version()).unwrap_or_default();
    let dps = (units::speed_dps(spd_ref, fw) * 1000.0).round() / 1000.0;
    if dev.and_then(|d| d.mode) == Some(CtrlMode::Speed) {
        sign * dps
    } else {
        dps
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, UNIX_EPOCH};

    use super::*;
    use crate::bus::handle::DeviceState;
    use crate::hands::Calibration;
    use crate::protocol::{Info02, Reply, ReplyBody};
    use crate::rosmsg::JointState;

    /// The sending ends a bus owner holds.
    struct Owner {
        _snapshots: watch::Sender<Arc<BusSnapshot>>,
        frames: broadcast::Sender<LoggedFrame>,
        _setpoints: broadcast::Sender<Commanded>,
        events: broadcast::Sender<BusEvent>,
    }

    /// Bus `l` with joints `ids` online; its frame tap holds `frames_len`.
    fn bus(ids: &[u8], frames_len: usize) -> (Owner, BusTap) {
        let mut snap = BusSnapshot::new("l", "/dev/null", 500_000);
        for &dev_id in ids {
            let dev = DeviceState {
                dev_id,
                online: true,
                ..DeviceState::default()
            };
            snap.devices.insert(dev_id, dev);
        }
        let (snap_tx, snapshots) = watch::channel(Arc::new(snap));
        let (frames_tx, frames) = broadcast::channel(frames_len);
        let (setpoints_tx, setpoints) = broadcast::channel(4);
        let (events_tx, events) = broadcast::channel(4);
        let taps = Taps {
            snapshots,
            frames,
            setpoints,
            events,
        };
        let labeler: Labeler =
            Arc::new(|bus: &str, id: u8| (format!("{bus}_{id}"), Calibration::IDENTITY));
        let owner = Owner {
            _snapshots: snap_tx,
            frames: frames_tx,
            _setpoints: setpoints_tx,
            events: events_tx,
        };
        (owner, BusTap::new("l", taps, labeler))
    }

    /// A status reply of joint `id` on the wire at `ms`.
    fn reply(id: u8, ms: u64) -> LoggedFrame {
        let body = ReplyBody::Info02(Info02 {
            d_cur: 0,
            q_cur: 0,
            speed: 0,
            angle: 0,
        });
        LoggedFrame {
            at: UNIX_EPOCH + Duration::from_millis(ms),
            tx: false,
            bytes: Reply::new(id, body).encode(),
        }
    }

    /// What one drain emits of the `wanted` topics.
    fn drain(tap: &mut BusTap, wanted: &[Topic]) -> Vec<(Topic, u64, Vec<u8>)> {
        let mut out = Vec::new();
        let drained = tap.drain(
            |t| wanted.contains(&t),
            |t, ns, data| {
                out.push((t, ns, data.to_vec()));
                Ok::<(), ()>(())
            },
        );
        assert_eq!(drained, Ok(()));
        out
    }

    #[test]
    fn a_round_of_replies_is_one_joint_state_stamped_with_the_newest() {
        let (owner, mut tap) = bus(&[1, 2], 16);
        owner.frames.send(reply(1, 10)).unwrap();
        owner.frames.send(reply(2, 12)).unwrap();
        let out = drain(&mut tap, &[Topic::JointStates]);
        assert_eq!(out.len(), 1, "frames not wanted: only the joint state");
        let (topic, ns, data) = &out[0];
        assert_eq!((*topic, *ns), (Topic::JointStates, 12_000_000));
        let msg = JointState::from_cdr(data).unwrap();
        assert_eq!(msg.name, ["l_1", "l_2"]);
        assert_eq!(msg.stamp_ns, 12_000_000, "the stamp is the log time");
    }

    #[test]
    fn frames_come_before_the_joint_state_they_complete() {
        let (owner, mut tap) = bus(&[1], 16);
        owner.frames.send(reply(1, 10)).unwrap();
        let out = drain(&mut tap, &Topic::ALL);
        let topics: Vec<Topic> = out.iter().map(|(t, _, _)| *t).collect();
        assert_eq!(topics, [Topic::Frames, Topic::JointStates]);
        let frame: serde_json::Value = serde_json::from_slice(&out[0].2).unwrap();
        assert_eq!(frame["dir"], "rx");
        assert_eq!(frame["wire_time_ns"], 10_000_000);
        assert_eq!(frame["hex"], hex(&reply(1, 10).bytes));
    }

    #[test]
    fn events_unwanted_are_read_not_encoded_and_a_lag_is_counted() {
        let (owner, mut tap) = bus(&[1], 4);
        let estop = || BusEvent::Estop { bus: "l".into() };
        owner.events.send(estop()).unwrap();
        assert!(drain(&mut tap, &[Topic::JointStates]).is_empty());
        owner.events.send(estop()).unwrap();
        let out = drain(&mut tap, &[Topic::Events]);
        assert_eq!(out.len(), 1, "the first was read by the drain before");
        let event: serde_json::Value = serde_json::from_slice(&out[0].2).unwrap();
        assert_eq!(event["event"], "estop");
        // Six frames into a tap of four: the two oldest are lost, counted.
        for ms in 0..6 {
            owner.frames.send(reply(1, ms)).unwrap();
        }
        let out = drain(&mut tap, &[Topic::Frames]);
        assert_eq!(out.len(), 4);
        assert_eq!(tap.lost(), 2);
    }
}
