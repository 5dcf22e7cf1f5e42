//! A bus's families: its line, the USB pipeline behind an adapter, its
//! devices' count, every engine counter (each with its help), its timing
//! and latencies.

use super::exposition::{label, Exposition};
use crate::bus::handle::LinkState;
use crate::bus::BusSnapshot;

/// `HELP` of each engine counter, by its field name in
/// [`BusCounters`](crate::bus::handle::BusCounters): a new counter must get
/// a line here (a test fails otherwise) and a row in `docs/metrics.md`.
const BUS_COUNTER_HELP: &[(&str, &str)] = &[
    (
        "frames_tx_broadcast",
        "Broadcast control frames (8 joints each) written.",
    ),
    (
        "frames_tx_control",
        "Per-device control frames (enable, disable, set-ref) written.",
    ),
    (
        "frames_tx_config",
        "Config/read frames (polls, reads, writes) written.",
    ),
    ("frames_tx_jog", "Jog frames written."),
    ("frames_rx", "Frames received with a good CRC."),
    ("crc_errors", "Received frames dropped for a bad CRC."),
    (
        "skipped_bytes",
        "Received bytes skipped while looking for a frame header (line noise).",
    ),
    (
        "timeouts",
        "Transactions whose reply did not come before the reply timeout.",
    ),
    (
        "retries",
        "One-shot transactions sent again after a timeout.",
    ),
    (
        "unsolicited",
        "Frames received that no transaction asked for (power-up announcements, late replies).",
    ),
    (
        "requests_queued",
        "Requests (REST/WebSocket one-shots) queued to the bus owner.",
    ),
    ("setpoints_sent", "Setpoints written to the wire."),
    (
        "reconnects",
        "Times the serial port was opened again after it was lost.",
    ),
    ("polls", "Telemetry polls (INFO reads) written."),
    (
        "setpoints_dropped",
        "Setpoints dropped because their id has no device on the bus.",
    ),
    (
        "setpoints_stale",
        "Setpoints dropped because their joint's motion epoch advanced after they were admitted (e-stop, disable, reset, fault, mode change, enable).",
    ),
    (
        "owner_panics",
        "Panics the bus owner caught (a bug): each reopened the port.",
    ),
    (
        "verify_retries",
        "Extra attempts to confirm a write (read-back or re-send).",
    ),
    (
        "writes_unverified",
        "Writes that stayed unconfirmed after their retries.",
    ),
    (
        "firmware_probes",
        "INFO_07 reads asking a device its firmware revision (firmware = auto).",
    ),
    (
        "firmware_probes_unanswered",
        "Firmware probe attempts with no reply: how V2.0.1 devices show themselves (not timeouts).",
    ),
    (
        "frames_tx_batched",
        "Control frames written in front of a poll in one write (one USB transfer), on a latent adapter.",
    ),
    (
        "polls_pipelined",
        "Polls written behind a USB adapter before the previous reply reached the host.",
    ),
    (
        "usb_writes_unclocked",
        "Polls written behind a USB adapter while its frame clock was not known (each held the wire a USB frame longer).",
    ),
    (
        "usb_writes_ambiguous",
        "Writes too close to a USB frame boundary to know which frame took them (the wire was held for the later).",
    ),
    (
        "usb_backoffs",
        "Times the USB pipeline backed off (pipelined to guarded to guarded with its guard widened to lockstep; pipelined to lockstep on CH340 and CP2102) on evidence of late writes: garbled bytes, a reply lost from a device that still answers, or late sentinels.",
    ),
    (
        "usb_recoveries",
        "Times the USB pipeline stepped back towards the adapter's bound after a clean while.",
    ),
    (
        "usb_sentinels",
        "Sentinel transfers answered: written a tenth of a USB frame before their boundary, the wire held a frame longer, to see late writes without a collision.",
    ),
    (
        "usb_sentinels_late",
        "Sentinel transfers whose write reached the adapter a frame late.",
    ),
    (
        "usb_writes_taken_late",
        "Confirmed writes seen taken half a USB frame or more after the boundary they were aimed at (late writes, and late looks at the count): each held the wire that much longer, no collision.",
    ),
    (
        "usb_counts_given_up",
        "Confirmed writes the port's output count still showed untaken 4 ms after their USB frame: the count is given up on, as evidence for the pipeline's guard.",
    ),
];

/// Every family of one bus, in the order a scrape shows them.
pub(super) fn bus_families(m: &mut Exposition, snap: &BusSnapshot) {
    let l = format!("bus=\"{}\"", label(&snap.name));
    line_families(m, snap, &l);
    usb_families(m, snap, &l);
    device_counts(m, snap, &l);
    counter_families(m, snap, &l);
    timing_families(m, snap, &l);
}

/// The line: up, its link state, baud, queue, polls in flight.
fn line_families(m: &mut Exposition, snap: &BusSnapshot, l: &str) {
    let up = snap.link == LinkState::Up;
    m.gauge(
        "jointd_bus_up",
        "1 when the bus's serial port is open and its owner running.",
        l,
        f64::from(u8::from(up)),
    );
    for state in ["opening", "up", "down"] {
        let is = snap.link.name() == state;
        m.gauge(
            "jointd_bus_link_state",
            "The bus's link state as a state set: 1 on the current state's line.",
            &format!("{l},state=\"{state}\""),
            f64::from(u8::from(is)),
        );
    }
    m.gauge(
        "jointd_bus_baud",
        "The bus's baud rate, bits per second.",
        l,
        f64::from(snap.baud),
    );
    m.gauge(
        "jointd_bus_queue_depth",
        "Requests waiting for the bus owner.",
        l,
        snap.queue_depth as f64,
    );
    m.gauge(
        "jointd_bus_polls_in_flight",
        "Polls written blind behind a USB adapter whose reply has not reached the host yet.",
        l,
        snap.polls_in_flight as f64,
    );
}

/// Behind a USB adapter: the pipeline's mode, guard, confirming, incidents.
fn usb_families(m: &mut Exposition, snap: &BusSnapshot, l: &str) {
    // Behind a native line every line is 0: the families are always there.
    let usb = snap.usb_pipeline.as_ref();
    for mode in crate::bus::usb::guard::PipelineMode::all() {
        m.gauge(
            "jointd_bus_usb_pipeline_mode",
            "Behind a USB adapter, the pipeline's mode as a state set: 1 on the current mode's line (all 0 on a native line).",
            &format!("{l},mode=\"{mode}\""),
            f64::from(u8::from(usb.is_some_and(|p| p.mode == mode))),
        );
    }
    m.gauge(
        "jointd_bus_usb_guard_seconds",
        "Behind a USB adapter, how late a write may reach it and still leave where the wire is held for it (0 on a native line).",
        l,
        usb.map_or(0.0, |p| p.guard_us as f64 / 1e6),
    );
    m.gauge(
        "jointd_bus_usb_arrival_lag_seconds",
        "Behind a USB adapter, how late the bus thread wakes (a high quantile of its timed waits): the frame clock learnt from reply arrivals may run this much behind the adapter's, and each write spares it before its boundary (0 on a native line).",
        l,
        usb.map_or(0.0, |p| p.arrival_lag_us as f64 / 1e6),
    );
    m.gauge(
        "jointd_bus_usb_confirming",
        "Behind a USB adapter, 1 while each write is seen taken by the adapter (the port's output count) before the next: late writes then cost time, never a collision.",
        l,
        f64::from(u8::from(usb.is_some_and(|p| p.confirming))),
    );
    m.gauge(
        "jointd_bus_usb_incidents_per_second",
        "Behind a USB adapter, evidence of collisions per second over the last 10 s.",
        l,
        usb.map_or(0.0, |p| p.incidents_per_s),
    );
}

/// Devices answering, devices known.
fn device_counts(m: &mut Exposition, snap: &BusSnapshot, l: &str) {
    let online = snap.devices.values().filter(|d| d.online).count();
    m.gauge(
        "jointd_bus_devices_online",
        "Devices answering their polls.",
        l,
        online as f64,
    );
    m.gauge(
        "jointd_bus_devices_known",
        "Devices the bus has seen, online or not.",
        l,
        snap.devices.len() as f64,
    );
}

/// Every counter the engine keeps, by its field name, with its help.
fn counter_families(m: &mut Exposition, snap: &BusSnapshot, l: &str) {
    if let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(&snap.counters) {
        for (field, value) in fields {
            let Some(v) = value.as_u64() else { continue };
            if field == "wire_busy_us" {
                m.counter(
                    "jointd_bus_wire_busy_seconds_total",
                    "Wire time the daemon scheduled (frames and reply turnarounds), seconds.",
                    l,
                    v as f64 / 1e6,
                );
                continue;
            }
            let help = BUS_COUNTER_HELP.iter().find(|(f, _)| *f == field).map_or(
                "An engine counter (undocumented: add it to BUS_COUNTER_HELP).",
                |(_, h)| h,
            );
            m.counter(&format!("jointd_bus_{field}_total"), help, l, v as f64);
        }
    }
}

/// The wire's use, the timing in force, latencies.
fn timing_families(m: &mut Exposition, snap: &BusSnapshot, l: &str) {
    m.gauge(
        "jointd_bus_wire_utilisation_ratio",
        "Share of the last second the daemon had the line busy (0..1).",
        l,
        snap.rates.wire_utilisation,
    );
    m.gauge(
        "jointd_bus_reply_timeout_seconds",
        "The reply timeout in force: request end to giving up.",
        l,
        snap.rates.reply_timeout_us as f64 / 1e6,
    );
    m.gauge(
        "jointd_bus_wake_lead_seconds",
        "How long before a reply is due the bus thread stops sleeping (how late its sleeps end).",
        l,
        snap.rates.wake_lead_us as f64 / 1e6,
    );
    m.gauge(
        "jointd_bus_reply_lag_seconds",
        "How long after the line model replies reach the bus thread (a low quantile): where it starts watching for one.",
        l,
        snap.rates.reply_lag_us as f64 / 1e6,
    );
    m.histogram(
        "jointd_bus_setpoint_to_wire_seconds",
        "A setpoint's acceptance to the last byte of its frame on the wire.",
        l,
        &snap.latency.setpoint_to_wire,
    );
    m.histogram(
        "jointd_bus_round_trip_seconds",
        "A config/read frame handed to the port to its reply read back.",
        l,
        &snap.latency.round_trip,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_engine_counter_has_help() {
        let fields = serde_json::to_value(crate::bus::handle::BusCounters::default()).unwrap();
        for field in fields.as_object().unwrap().keys() {
            if field == "wire_busy_us" {
                continue;
            }
            assert!(
                BUS_COUNTER_HELP.iter().any(|(f, _)| f == field),
                "counter `{field}` has no HELP line"
            );
        }
    }
}
