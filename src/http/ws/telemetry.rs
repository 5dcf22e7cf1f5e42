//! Builds `telemetry` messages from the buses' latest snapshots: whatever
//! is newest when the client can take it, in physical units.

use std::sync::Arc;
use std::time::Instant;

use serde::ser::{Serialize, SerializeMap, Serializer};
use serde_json::Value;

use super::messages::Field;
use crate::bus::handle::DeviceState;
use crate::bus::BusSnapshot;
use crate::hands::Calibration;
use crate::http::hub::FragmentCache;
use crate::http::telemetry::{
    disabled_reason, firmware_of, measured_angle_raw, revision_of, round3,
};
use crate::protocol::status::{active_fault, fault_name, fsm_name_in};
use crate::protocol::units;

/// What a client asked to receive.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Subscription {
    pub buses: Vec<String>,
    /// `None`: every device.
    pub devices: Option<Vec<u8>>,
    pub fields: Vec<Field>,
    pub rate_hz: f64,
    /// Per bus (in `buses`' order), the key of its joints' fragment in the
    /// shared cache: made once here, not at every tick of every client.
    shapes: Vec<String>,
}

impl Subscription {
    pub(crate) fn new(
        buses: Vec<String>,
        devices: Option<Vec<u8>>,
        fields: Vec<Field>,
        rate_hz: f64,
    ) -> Self {
        let shapes = buses
            .iter()
            .map(|bus| format!("{bus}|{devices:?}|{fields:?}"))
            .collect();
        Self {
            buses,
            devices,
            fields,
            rate_hz,
            shapes,
        }
    }

    /// Each bus with its fragment's cache key.
    pub(crate) fn buses_and_shapes(&self) -> impl Iterator<Item = (&str, &str)> {
        self.buses
            .iter()
            .map(String::as_str)
            .zip(self.shapes.iter().map(String::as_str))
    }
}

/// Age of the newest sample of the joint.
fn age_ms(dev: &DeviceState, now: Instant) -> Option<f64> {
    let newest = [
        dev.info01.as_ref().map(|x| x.1),
        dev.info02.as_ref().map(|x| x.1),
    ]
    .into_iter()
    .flatten()
    .max()?;
    Some(round3(
        now.saturating_duration_since(newest).as_secs_f64() * 1000.0,
    ))
}

pub(crate) fn field_name(f: Field) -> &'static str {
    match f {
        Field::AngleDeg => "angle_deg",
        Field::TargetDeg => "target_deg",
        Field::SpeedDps => "speed_dps",
        Field::QCurrentA => "q_current_a",
        Field::State => "state",
        Field::Fault => "fault",
        Field::TempC => "temp_c",
        Field::VbusV => "vbus_v",
    }
}

fn field_value(f: Field, dev: &DeviceState, cal: &Calibration) -> Value {
    let info01 = dev.info01.as_ref().map(|x| x.0);
    let info02 = dev.info02.as_ref().map(|x| x.0);
    let angle = |raw: i16| Value::from(cal.to_joint(units::angle_deg(raw)));
    let v = match f {
        Field::AngleDeg => measured_angle_raw(dev).map(angle),
        Field::TargetDeg => dev.target_sent.map(|t| angle(t.pos_ref)),
        Field::SpeedDps => {
            let dps =
                |i: crate::protocol::Info02| units::output_deg_per_s(i.speed_rpm(firmware_of(dev)));
            info02.map(|i| Value::from(round3(cal.sign() * dps(i))))
        }
        Field::QCurrentA => {
            info02.map(|i| Value::from(round3(cal.sign() * units::current_a(i.q_cur))))
        }
        Field::State => info01.map(|i| Value::from(fsm_name_in(i.fsm, revision_of(dev)))),
        Field::Fault => info01.map(|i| Value::from(fault_name(active_fault(i.err_code)))),
        Field::TempC => info01.map(|i| Value::from(i.temp_c())),
        Field::VbusV => info01.map(|i| Value::from(i.vbus_v())),
    };
    v.unwrap_or(Value::Null)
}

/// The joints of `snap` for `sub`, comma-separated JSON objects, from the
/// cache shared by every connection with the same subscription shape.
/// `age_ms` in a shared fragment is the age when it was built (at most one
/// snapshot interval earlier than the message).
pub(crate) fn fragment<'a>(
    cache: &FragmentCache,
    sub: &Subscription,
    shape: &str,
    snap: &Arc<BusSnapshot>,
    name_of: impl Fn(u8) -> Option<&'a str>,
    cal_of: impl Fn(u8) -> Calibration,
    now: Instant,
) -> Arc<str> {
    cache.get_or_build(shape, snap, || {
        let mut text = Vec::new();
        for dev in selected(sub, snap) {
            let joint = JointJson {
                sub,
                bus: &snap.name,
                dev,
                cal: cal_of(dev.dev_id),
                name: name_of(dev.dev_id),
                now,
            };
            let mark = text.len();
            if mark > 0 {
                text.push(b',');
            }
            if let Err(e) = serde_json::to_writer(&mut text, &joint) {
                tracing::error!(%e, "could not write a joint's telemetry");
                text.truncate(mark);
            }
        }
        // serde_json writes UTF-8 only.
        String::from_utf8(text).unwrap_or_default()
    })
}

/// The devices of `snap` the subscription asks for, in id order.
fn selected<'a>(
    sub: &'a Subscription,
    snap: &'a BusSnapshot,
) -> impl Iterator<Item = &'a DeviceState> + 'a {
    snap.devices.values().filter(move |dev| {
        sub.devices
            .as_ref()
            .map_or(true, |ids| ids.contains(&dev.dev_id))
    })
}

/// One joint of a subscription as its telemetry object, written straight
/// to JSON at each build: the keys in sorted order (as a `serde_json::Map`
/// gives them, the bytes clients have always read) without a map of owned
/// keys made and dropped per joint. `age_ms` and `name` always;
/// `target_known` beside `target_deg` (`null` with `false` is unknown, not
/// idle); `disabled_reason` beside `state` (why the joint is disabled, if
/// known).
struct JointJson<'a> {
    sub: &'a Subscription,
    bus: &'a str,
    dev: &'a DeviceState,
    cal: Calibration,
    name: Option<&'a str>,
    now: Instant,
}

impl Serialize for JointJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let (dev, cal) = (self.dev, &self.cal);
        let has = |f: Field| self.sub.fields.contains(&f);
        let mut m = s.serialize_map(None)?;
        // A subscribed field, by its name.
        let field = |m: &mut S::SerializeMap, f: Field| {
            if has(f) {
                m.serialize_entry(field_name(f), &field_value(f, dev, cal))?;
            }
            Ok(())
        };
        m.serialize_entry("age_ms", &age_ms(dev, self.now))?;
        field(&mut m, Field::AngleDeg)?;
        m.serialize_entry("bus", self.bus)?;
        if has(Field::State) {
            m.serialize_entry("disabled_reason", &disabled_reason(dev))?;
        }
        field(&mut m, Field::Fault)?;
        m.serialize_entry("id", &dev.dev_id)?;
        if let Some(name) = self.name {
            m.serialize_entry("name", name)?;
        }
        m.serialize_entry("online", &dev.online)?;
        for f in [
            Field::QCurrentA,
            Field::SpeedDps,
            Field::State,
            Field::TargetDeg,
        ] {
            field(&mut m, f)?;
        }
        if has(Field::TargetDeg) {
            m.serialize_entry("target_known", &dev.target_known)?;
        }
        field(&mut m, Field::TempC)?;
        field(&mut m, Field::VbusV)?;
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use serde_json::Map;

    use super::*;
    use crate::bus::state::DisabledReason;
    use crate::protocol::{Info01, Info02};

    // The map-built objects these bytes were first made of: the oracle.
    /// The joints of one bus snapshot that the subscription selects;
    /// `name_of` gives a joint's configured name, `cal_of` its calibration
    /// (angles, speeds and currents are reported in the calibrated frame).
    fn joints<'a>(
        sub: &Subscription,
        snap: &BusSnapshot,
        name_of: impl Fn(u8) -> Option<&'a str>,
        cal_of: impl Fn(u8) -> Calibration,
        now: Instant,
        out: &mut Vec<Map<String, Value>>,
    ) {
        for dev in selected(sub, snap) {
            let mut m = joint(sub, &snap.name, dev, &cal_of(dev.dev_id), now);
            if let Some(name) = name_of(dev.dev_id) {
                m.insert("name".into(), name.into());
            }
            out.push(m);
        }
    }

    fn joint(
        sub: &Subscription,
        bus: &str,
        dev: &DeviceState,
        cal: &Calibration,
        now: Instant,
    ) -> Map<String, Value> {
        let mut m = Map::new();
        m.insert("bus".into(), bus.into());
        m.insert("id".into(), dev.dev_id.into());
        m.insert("online".into(), dev.online.into());
        m.insert(
            "age_ms".into(),
            age_ms(dev, now).map_or(Value::Null, Value::from),
        );
        for f in &sub.fields {
            m.insert(field_name(*f).into(), field_value(*f, dev, cal));
            if *f == Field::TargetDeg {
                // `target_deg: null` with `target_known: false` is unknown, not idle.
                m.insert("target_known".into(), dev.target_known.into());
            }
            if *f == Field::State {
                // Beside the state: why the joint is disabled, if known.
                let reason = disabled_reason(dev).map_or(Value::Null, Value::from);
                m.insert("disabled_reason".into(), reason);
            }
        }
        m
    }

    fn snapshot(now: Instant) -> BusSnapshot {
        let mut snap = BusSnapshot::new("sim0", "/dev/null", 500_000);
        let info01 = Info01 {
            fsm: 3,
            err_code: 0,
            soft_ver: 128,
            temp_raw: 80,
            angle: -1234,
            vbus: 3100,
        };
        let info02 = Info02 {
            d_cur: 10,
            q_cur: -2000,
            speed: 1500,
            angle: -1230,
        };
        let devices = [
            DeviceState {
                dev_id: 1,
                online: true,
                info01: Some((info01, now)),
                info02: Some((info02, now)),
                target_sent: Some(crate::bus::Setpoint {
                    pos_ref: 640,
                    spd_ref: 100,
                }),
                target_known: true,
                ..Default::default()
            },
            DeviceState {
                dev_id: 2,
                online: false,
                disabled_reason: Some(DisabledReason::Reset),
                ..Default::default()
            },
            DeviceState {
                dev_id: 7,
                online: true,
                info01: Some((
                    Info01 {
                        err_code: 4,
                        ..info01
                    },
                    now,
                )),
                ..Default::default()
            },
        ];
        snap.devices = devices
            .into_iter()
            .map(|d| (d.dev_id, d))
            .collect::<BTreeMap<_, _>>();
        snap
    }

    #[test]
    fn fragments_write_the_bytes_the_maps_did() {
        let now = Instant::now();
        let snap = Arc::new(snapshot(now));
        let flipped = Calibration {
            offset_deg: 12.5,
            flip: true,
            ..Calibration::IDENTITY
        };
        let cal_of = |id: u8| {
            if id == 7 {
                flipped
            } else {
                Calibration::IDENTITY
            }
        };
        let name_of = |id: u8| (id == 1).then_some("index");
        let every: Vec<Field> = Field::ALL.to_vec();
        let shapes: Vec<(Option<Vec<u8>>, Vec<Field>)> = vec![
            (None, every.clone()),
            (None, vec![]),
            (Some(vec![7, 2]), vec![Field::State, Field::TargetDeg]),
            (None, vec![Field::VbusV, Field::AngleDeg, Field::VbusV]),
            (Some(vec![9]), every),
        ];
        for (devices, fields) in shapes {
            let sub = Subscription::new(vec!["sim0".into()], devices, fields, 100.0);
            let mut maps = Vec::new();
            joints(&sub, &snap, name_of, cal_of, now, &mut maps);
            let want: Vec<String> = maps
                .iter()
                .map(|m| Value::Object(m.clone()).to_string())
                .collect();
            let cache = FragmentCache::default();
            let got = fragment(&cache, &sub, "shape", &snap, name_of, cal_of, now);
            assert_eq!(&*got, want.join(","), "{sub:?}");
        }
    }
}
