//! Each device's families: online, rates, resets, and what its latest
//! status (INFO_01) and telemetry (INFO_02) say, each with its age.

use std::time::Instant;

use super::exposition::{label, Exposition};
use crate::bus::handle::DeviceState;
use crate::bus::BusSnapshot;
use crate::http::telemetry::revision_of;
use crate::protocol::reply::{Info01, Info02};
use crate::protocol::status::{active_fault, fault_history, fault_name, fsm_name_in};

pub(super) fn device_families(m: &mut Exposition, snap: &BusSnapshot, now: Instant) {
    let bus = label(&snap.name);
    for dev in snap.devices.values() {
        let l = format!("bus=\"{bus}\",id=\"{}\"", dev.dev_id);
        m.gauge(
            "jointd_device_online",
            "1 while the device answers its polls.",
            &l,
            f64::from(u8::from(dev.online)),
        );
        m.gauge(
            "jointd_device_control_rate_hertz",
            "Setpoints reaching the wire per second for this joint.",
            &l,
            dev.control_hz,
        );
        m.gauge(
            "jointd_device_telemetry_rate_hertz",
            "Telemetry samples per second from this joint.",
            &l,
            dev.telemetry_hz,
        );
        m.counter(
            "jointd_device_resets_total",
            "Power cuts and reboots the daemon detected.",
            &l,
            dev.resets as f64,
        );
        if let Some((i, at)) = &dev.info01 {
            status_families(
                m,
                &l,
                dev,
                i,
                now.saturating_duration_since(*at).as_secs_f64(),
            );
        }
        if let Some((i, at)) = &dev.info02 {
            motion_families(m, &l, i, now.saturating_duration_since(*at).as_secs_f64());
        }
    }
}

/// What the latest INFO_01 says: state, faults, temperature, supply, its age.
fn status_families(m: &mut Exposition, l: &str, dev: &DeviceState, i: &Info01, age: f64) {
    m.gauge(
        "jointd_device_state",
        "The device's state machine state (from INFO_01) as a label; always 1.",
        &format!("{l},state=\"{}\"", fsm_name_in(i.fsm, revision_of(dev))),
        1.0,
    );
    m.gauge(
        "jointd_device_fault",
        "The device's active fault and latched fault history as labels; always 1.",
        &format!(
            "{l},active=\"{}\",history=\"{}\"",
            fault_name(active_fault(i.err_code)),
            fault_name(fault_history(i.err_code))
        ),
        1.0,
    );
    m.gauge(
        "jointd_device_temperature_celsius",
        "Driver temperature.",
        l,
        i.temp_c(),
    );
    m.gauge(
        "jointd_device_bus_voltage_volts",
        "Supply voltage the device measures.",
        l,
        i.vbus_v(),
    );
    m.gauge(
        "jointd_device_status_age_seconds",
        "Age of the latest INFO_01 status.",
        l,
        age,
    );
}

/// What the latest INFO_02 says: angle, q current, its age.
fn motion_families(m: &mut Exposition, l: &str, i: &Info02, age: f64) {
    let q = crate::protocol::units::current_a(i.q_cur);
    m.gauge(
        "jointd_device_angle_degrees",
        "Output shaft angle.",
        l,
        i.angle_deg(),
    );
    m.gauge(
        "jointd_device_q_current_amperes",
        "Q-axis (torque) current.",
        l,
        q,
    );
    m.gauge(
        "jointd_device_telemetry_age_seconds",
        "Age of the latest INFO_02 telemetry.",
        l,
        age,
    );
}
