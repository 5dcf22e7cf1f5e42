//! `/diagnostics` (`diagnostic_msgs/msg/DiagnosticArray`) at
//! `diagnostics_hz`: one `DiagnosticStatus` per bus (its link, how busy
//! the line is, timeouts and CRC errors) and one per joint (state, fault,
//! temperature, voltage, online).

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use super::keys;
use crate::bus::handle::LinkState;
use crate::bus::BusSnapshot;
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;
use crate::protocol::status::{active_fault, fault_name, fsm_name_in};
use crate::record::joint_states::system_ns;
use crate::rosmsg::{diagnostic_array_cdr, DiagnosticStatus};

pub(super) async fn publish(
    state: Arc<Control>,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    period: Duration,
    stats: Arc<Ros2Stats>,
) {
    let mut tick = tokio::time::interval(period);
    let mut sequence = 0i64;
    let label = state.joint_labeler();
    loop {
        tick.tick().await;
        let mut status = Vec::new();
        for bus in state.readers() {
            let snap = bus.snapshot();
            status.push(bus_status(&snap));
            for dev in snap.devices.values() {
                let (name, _) = label(bus.name(), dev.dev_id);
                status.push(joint_status(bus.name(), &name, dev));
            }
        }
        sequence += 1;
        let ns = i64::try_from(system_ns(SystemTime::now())).unwrap_or(i64::MAX);
        let cdr = diagnostic_array_cdr(u64::try_from(ns).unwrap_or(0), "", &status);
        if publisher
            .put(cdr)
            .attachment(keys::attachment(sequence, ns, &gid))
            .await
            .is_ok()
        {
            stats.diagnostics.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// One joint as `diagnostic_msgs/DiagnosticStatus`: OK running or ready,
/// WARN disabled by something, ERROR faulted, STALE offline.
fn joint_status(bus: &str, name: &str, dev: &crate::bus::handle::DeviceState) -> DiagnosticStatus {
    let info = dev.info01.as_ref().map(|(i, _)| *i);
    let fault = info.map_or(0, |i| active_fault(i.err_code));
    let (level, message) = if !dev.online {
        (3, "offline".to_string())
    } else if fault != 0 {
        (2, format!("fault: {}", fault_name(fault)))
    } else if let Some(reason) = dev.disabled_reason {
        (1, format!("disabled ({})", reason.name()))
    } else {
        (
            0,
            info.map_or("no status yet".into(), |i| {
                fsm_name_in(i.fsm, dev.firmware.map(|f| f.revision)).to_string()
            }),
        )
    };
    let mut values = vec![
        ("bus".to_string(), bus.to_string()),
        ("id".to_string(), dev.dev_id.to_string()),
        ("online".to_string(), dev.online.to_string()),
    ];
    if let Some(i) = info {
        values.push((
            "state".into(),
            fsm_name_in(i.fsm, dev.firmware.map(|f| f.revision)).into(),
        ));
        values.push(("fault".into(), fault_name(fault).into()));
        values.push(("temperature_c".into(), format!("{:.1}", i.temp_c())));
        values.push(("voltage_v".into(), format!("{:.2}", i.vbus_v())));
    }
    DiagnosticStatus {
        level,
        name: format!("jointd: {name}"),
        message,
        hardware_id: format!("{bus}/{}", dev.dev_id),
        values,
    }
}

/// One bus as `diagnostic_msgs/DiagnosticStatus`: OK with its link up,
/// WARN while it opens, ERROR when it is down; the counters since start
/// and the rates of the last statistics window as values.
fn bus_status(snap: &BusSnapshot) -> DiagnosticStatus {
    let (level, message) = match &snap.link {
        LinkState::Up => (0, "link up".to_string()),
        LinkState::Opening => (1, "opening the port".to_string()),
        LinkState::Down { reason, .. } => (2, format!("link down: {reason}")),
    };
    let online = snap.devices.values().filter(|d| d.online).count();
    let (c, r) = (&snap.counters, &snap.rates);
    let values = vec![
        ("link".to_string(), snap.link.name().to_string()),
        ("port".into(), snap.path.clone()),
        ("baud".into(), snap.baud.to_string()),
        (
            "devices_online".into(),
            format!("{online}/{}", snap.devices.len()),
        ),
        (
            "occupancy_pct".into(),
            format!("{:.1}", r.wire_utilisation * 100.0),
        ),
        ("timeouts".into(), c.timeouts.to_string()),
        ("timeouts_per_s".into(), format!("{:.2}", r.timeouts_per_s)),
        ("crc_errors".into(), c.crc_errors.to_string()),
        ("frames_rx".into(), c.frames_rx.to_string()),
        ("reconnects".into(), c.reconnects.to_string()),
        ("queue_depth".into(), snap.queue_depth.to_string()),
    ];
    DiagnosticStatus {
        level,
        name: format!("jointd: bus {}", snap.name),
        message,
        hardware_id: snap.path.clone(),
        values,
    }
}
