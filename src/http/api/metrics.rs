//! The Prometheus text exposition of `/metrics`, written by hand: every
//! value already lives in the bus snapshots and the WebSocket hub, so a
//! scrape only formats them, and a registry crate (`prometheus-client`)
//! would add a second copy of each counter to keep in step, or a custom
//! collector doing what this file does. `promtool check metrics` judges
//! the output in CI (`.ci/run`); `docs/metrics.md` lists every family, and
//! a test keeps that list and this file in step.
//!
//! Conventions (Prometheus' naming guide): base units (seconds, volts,
//! amperes, hertz, ratios 0..1 named `_ratio`), counters end in `_total`,
//! rates are left to PromQL's `rate()` over the counters, latencies are
//! histograms, states are labels.

mod build_info;
mod http_requests;
mod process;

use std::fmt::Write as _;
use std::time::Instant;

use crate::bus::handle::LinkState;
use crate::bus::BusSnapshot;
use crate::histogram::Histogram;
use crate::http::hub::WsHub;
use crate::http::state::AppState;
use crate::http::telemetry::revision_of;
use crate::protocol::status::{active_fault, fault_history, fault_name, fsm_name_in};

/// Content type of the Prometheus text exposition format.
pub(crate) const PROMETHEUS_TEXT: &str = "text/plain; version=0.0.4; charset=utf-8";

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

/// Builds the exposition: families in order of first use, each with one
/// `HELP` and one `TYPE` line and its samples together.
#[derive(Default)]
struct Exposition {
    families: Vec<Family>,
}

struct Family {
    name: String,
    kind: &'static str,
    help: String,
    lines: Vec<String>,
}

impl Exposition {
    fn family(&mut self, name: &str, kind: &'static str, help: &str) -> &mut Vec<String> {
        let i = match self.families.iter().position(|f| f.name == name) {
            Some(i) => i,
            None => {
                self.families.push(Family {
                    name: name.to_owned(),
                    kind,
                    help: help.to_owned(),
                    lines: Vec::new(),
                });
                self.families.len() - 1
            }
        };
        &mut self.families[i].lines
    }

    fn sample(&mut self, name: &str, kind: &'static str, help: &str, labels: &str, value: f64) {
        let line = if labels.is_empty() {
            format!("{name} {value}")
        } else {
            format!("{name}{{{labels}}} {value}")
        };
        self.family(name, kind, help).push(line);
    }

    fn gauge(&mut self, name: &str, help: &str, labels: &str, value: f64) {
        self.sample(name, "gauge", help, labels, value);
    }

    fn counter(&mut self, name: &str, help: &str, labels: &str, value: f64) {
        self.sample(name, "counter", help, labels, value);
    }

    fn histogram(&mut self, name: &str, help: &str, labels: &str, h: &Histogram) {
        let sep = if labels.is_empty() { "" } else { "," };
        let lines = self.family(name, "histogram", help);
        for (le, n) in h.cumulative() {
            lines.push(format!("{name}_bucket{{{labels}{sep}le=\"{le}\"}} {n}"));
        }
        lines.push(format!(
            "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {}",
            h.count()
        ));
        let braces = |l: &str| {
            if l.is_empty() {
                String::new()
            } else {
                format!("{{{l}}}")
            }
        };
        lines.push(format!("{name}_sum{} {}", braces(labels), h.sum_seconds()));
        lines.push(format!("{name}_count{} {}", braces(labels), h.count()));
    }

    fn render(&self) -> String {
        let mut out = String::new();
        for f in &self.families {
            let _ = writeln!(out, "# HELP {} {}", f.name, f.help);
            let _ = writeln!(out, "# TYPE {} {}", f.name, f.kind);
            for line in &f.lines {
                let _ = writeln!(out, "{line}");
            }
        }
        out
    }
}

/// A label value with `\`, `"` and newlines escaped.
fn label(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

/// The whole exposition of the daemon now.
pub(crate) fn render(state: &AppState) -> String {
    let mut m = Exposition::default();
    build_info::family(&mut m);
    process::families(&mut m);
    m.gauge(
        "jointd_uptime_seconds",
        "Seconds since the daemon started.",
        "",
        state.uptime_s(),
    );
    let now = Instant::now();
    for bus in state.control().buses() {
        let snap = bus.snapshot();
        bus_families(&mut m, &snap);
        m.gauge(
            "jointd_bus_current_limits_owed",
            "Joints whose current limit a grasp or homing lowered and could not write back yet \
             (nothing new moves them until it is).",
            &format!("bus=\"{}\"", label(&snap.name)),
            bus.owed_limits().len() as f64,
        );
        device_families(&mut m, &snap, now);
    }
    ws_families(&mut m, state.ws());
    http_requests::families(&mut m, state);
    bridge_families(&mut m, state);
    m.render()
}

fn bus_families(m: &mut Exposition, snap: &BusSnapshot) {
    let l = format!("bus=\"{}\"", label(&snap.name));
    let online = snap.devices.values().filter(|d| d.online).count();
    let up = snap.link == LinkState::Up;
    m.gauge(
        "jointd_bus_up",
        "1 when the bus's serial port is open and its owner running.",
        &l,
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
        &l,
        f64::from(snap.baud),
    );
    m.gauge(
        "jointd_bus_queue_depth",
        "Requests waiting for the bus owner.",
        &l,
        snap.queue_depth as f64,
    );
    m.gauge(
        "jointd_bus_polls_in_flight",
        "Polls written blind behind a USB adapter whose reply has not reached the host yet.",
        &l,
        snap.polls_in_flight as f64,
    );
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
        &l,
        usb.map_or(0.0, |p| p.guard_us as f64 / 1e6),
    );
    m.gauge(
        "jointd_bus_usb_confirming",
        "Behind a USB adapter, 1 while each write is seen taken by the adapter (the port's output count) before the next: late writes then cost time, never a collision.",
        &l,
        f64::from(u8::from(usb.is_some_and(|p| p.confirming))),
    );
    m.gauge(
        "jointd_bus_usb_incidents_per_second",
        "Behind a USB adapter, evidence of collisions per second over the last 10 s.",
        &l,
        usb.map_or(0.0, |p| p.incidents_per_s),
    );
    m.gauge(
        "jointd_bus_devices_online",
        "Devices answering their polls.",
        &l,
        online as f64,
    );
    m.gauge(
        "jointd_bus_devices_known",
        "Devices the bus has seen, online or not.",
        &l,
        snap.devices.len() as f64,
    );
    // Every counter the engine keeps, by its field name, with its help.
    if let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(&snap.counters) {
        for (field, value) in fields {
            let Some(v) = value.as_u64() else { continue };
            if field == "wire_busy_us" {
                m.counter(
                    "jointd_bus_wire_busy_seconds_total",
                    "Wire time the daemon scheduled (frames and reply turnarounds), seconds.",
                    &l,
                    v as f64 / 1e6,
                );
                continue;
            }
            let help = BUS_COUNTER_HELP.iter().find(|(f, _)| *f == field).map_or(
                "An engine counter (undocumented: add it to BUS_COUNTER_HELP).",
                |(_, h)| h,
            );
            m.counter(&format!("jointd_bus_{field}_total"), help, &l, v as f64);
        }
    }
    m.gauge(
        "jointd_bus_wire_utilisation_ratio",
        "Share of the last second the daemon had the line busy (0..1).",
        &l,
        snap.rates.wire_utilisation,
    );
    m.gauge(
        "jointd_bus_reply_timeout_seconds",
        "The reply timeout in force: request end to giving up.",
        &l,
        snap.rates.reply_timeout_us as f64 / 1e6,
    );
    m.gauge(
        "jointd_bus_wake_lead_seconds",
        "How long before a reply is due the bus thread stops sleeping (how late its sleeps end).",
        &l,
        snap.rates.wake_lead_us as f64 / 1e6,
    );
    m.gauge(
        "jointd_bus_reply_lag_seconds",
        "How long after the line model replies reach the bus thread (a low quantile): where it starts watching for one.",
        &l,
        snap.rates.reply_lag_us as f64 / 1e6,
    );
    m.histogram(
        "jointd_bus_setpoint_to_wire_seconds",
        "A setpoint's acceptance to the last byte of its frame on the wire.",
        &l,
        &snap.latency.setpoint_to_wire,
    );
    m.histogram(
        "jointd_bus_round_trip_seconds",
        "A config/read frame handed to the port to its reply read back.",
        &l,
        &snap.latency.round_trip,
    );
}

fn device_families(m: &mut Exposition, snap: &BusSnapshot, now: Instant) {
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
            let age = now.saturating_duration_since(*at).as_secs_f64();
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
                &l,
                i.temp_c(),
            );
            m.gauge(
                "jointd_device_bus_voltage_volts",
                "Supply voltage the device measures.",
                &l,
                i.vbus_v(),
            );
            m.gauge(
                "jointd_device_status_age_seconds",
                "Age of the latest INFO_01 status.",
                &l,
                age,
            );
        }
        if let Some((i, at)) = &dev.info02 {
            let age = now.saturating_duration_since(*at).as_secs_f64();
            let q = crate::protocol::units::current_a(i.q_cur);
            m.gauge(
                "jointd_device_angle_degrees",
                "Output shaft angle.",
                &l,
                i.angle_deg(),
            );
            m.gauge(
                "jointd_device_q_current_amperes",
                "Q-axis (torque) current.",
                &l,
                q,
            );
            m.gauge(
                "jointd_device_telemetry_age_seconds",
                "Age of the latest INFO_02 telemetry.",
                &l,
                age,
            );
        }
    }
}

/// The ROS 2 bridge's counters (zero when it does not run) and the
/// recordings running.
fn bridge_families(m: &mut Exposition, state: &AppState) {
    let stats = state.control().ros2();
    m.gauge(
        "jointd_ros2_enabled",
        "1 when the ROS 2 bridge runs.",
        "",
        if stats.is_some() { 1.0 } else { 0.0 },
    );
    let connected = stats.is_some_and(|s| s.connected.load(std::sync::atomic::Ordering::Relaxed));
    m.gauge(
        "jointd_ros2_connected",
        "1 when the ROS 2 bridge has a Zenoh session (in client mode: a router reachable).",
        "",
        if connected { 1.0 } else { 0.0 },
    );
    type Field = fn(&crate::control::ros2_stats::Ros2Stats) -> &std::sync::atomic::AtomicU64;
    let counters: [(&str, &str, Field); 8] = [
        (
            "jointd_ros2_connects_total",
            "Zenoh sessions the ROS 2 bridge opened (reconnections included).",
            |s| &s.connects,
        ),
        (
            "jointd_ros2_joint_states_total",
            "JointState messages published.",
            |s| &s.joint_states,
        ),
        (
            "jointd_ros2_diagnostics_total",
            "DiagnosticArray messages published.",
            |s| &s.diagnostics,
        ),
        (
            "jointd_ros2_commands_applied_total",
            "joint_commands applied.",
            |s| &s.commands_applied,
        ),
        (
            "jointd_ros2_commands_dropped_total",
            "joint_commands refused whole.",
            |s| &s.commands_dropped,
        ),
        (
            "jointd_ros2_watchdog_fired_total",
            "Times the ROS 2 command stream stopped and the watchdog acted.",
            |s| &s.watchdog_fired,
        ),
        (
            "jointd_ros2_frames_lost_total",
            "Frames the bridge fell too far behind to see.",
            |s| &s.frames_lost,
        ),
        (
            "jointd_ros2_publish_errors_total",
            "Messages Zenoh would not publish.",
            |s| &s.publish_errors,
        ),
    ];
    for (name, help, field) in counters {
        let v = stats.map_or(0, |s| field(s).load(std::sync::atomic::Ordering::Relaxed));
        m.counter(name, help, "", v as f64);
    }
    m.gauge(
        "jointd_recordings_running",
        "MCAP recordings being written.",
        "",
        crate::control::recordings::running(state.control()) as f64,
    );
}

/// WebSocket counters over all connections since start.
fn ws_families(m: &mut Exposition, ws: &WsHub) {
    let get =
        |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed) as f64;
    m.gauge(
        "jointd_ws_connections",
        "Open WebSocket sessions.",
        "",
        get(&ws.connections),
    );
    m.counter(
        "jointd_ws_dropped_samples_total",
        "Telemetry samples skipped because a client was slow.",
        "",
        get(&ws.dropped_samples),
    );
    m.counter(
        "jointd_ws_dropped_events_total",
        "Events skipped because a client was slow.",
        "",
        get(&ws.dropped_events),
    );
    m.counter(
        "jointd_ws_dropped_replies_total",
        "Replies dropped because a client's reply queue was full.",
        "",
        get(&ws.dropped_replies),
    );
    m.counter(
        "jointd_ws_unsent_replies_total",
        "Replies to requests that never reached the client (it went away).",
        "",
        get(&ws.unsent_replies),
    );
    m.counter(
        "jointd_ws_slow_disconnects_total",
        "Clients closed with 1008 \"too slow\".",
        "",
        get(&ws.slow_disconnects),
    );
    m.histogram(
        "jointd_ws_send_seconds",
        "Writing one message to a client's socket.",
        "",
        &ws.send_latency(),
    );
    // Per connected client; the line goes with the connection.
    for (client, dropped) in ws.client_drops() {
        m.counter(
            "jointd_ws_client_dropped_samples_total",
            "Telemetry samples skipped for this connected client.",
            &format!("client=\"{client}\""),
            dropped as f64,
        );
    }
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

    #[test]
    fn a_histogram_renders_cumulative_buckets_sum_and_count() {
        let mut h = Histogram::default();
        h.observe(std::time::Duration::from_micros(300));
        h.observe(std::time::Duration::from_millis(2));
        let mut m = Exposition::default();
        m.histogram("x_seconds", "X.", "bus=\"a\"", &h);
        let text = m.render();
        assert!(
            text.contains("# HELP x_seconds X.\n# TYPE x_seconds histogram\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"0.0005\"} 1\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"0.0025\"} 2\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"+Inf\"} 2\n"),
            "{text}"
        );
        assert!(text.contains("x_seconds_count{bus=\"a\"} 2\n"), "{text}");
    }
}
