//! Builds `telemetry` messages from the buses' latest snapshots: whatever
//! is newest when the client can take it, in physical units.

use std::sync::Arc;
use std::time::Instant;

use serde_json::{Map, Value};

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

/// The joints of one bus snapshot that the subscription selects;
/// `name_of` gives a joint's configured name, `cal_of` its calibration
/// (angles, speeds and currents are reported in the calibrated frame).
pub(crate) fn joints<'a>(
    sub: &Subscription,
    snap: &BusSnapshot,
    name_of: impl Fn(u8) -> Option<&'a str>,
    cal_of: impl Fn(u8) -> Calibration,
    now: Instant,
    out: &mut Vec<Map<String, Value>>,
) {
    for dev in snap.devices.values() {
        if sub
            .devices
            .as_ref()
            .is_some_and(|ids| !ids.contains(&dev.dev_id))
        {
            continue;
        }
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
        let mut list = Vec::new();
        joints(sub, snap, name_of, cal_of, now, &mut list);
        // Each joint's map written as it is, not copied into a `Value` first.
        let mut text = String::new();
        for joint in &list {
            match serde_json::to_string(joint) {
                Ok(j) if text.is_empty() => text = j,
                Ok(j) => {
                    text.push(',');
                    text.push_str(&j);
                }
                Err(e) => tracing::error!(%e, "could not write a joint's telemetry"),
            }
        }
        text
    })
}
