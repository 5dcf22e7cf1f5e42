//! The ROS 2 bridge's families (zero while it does not run), the
//! recordings running, and the live Foxglove view's families (zero while
//! it does not run).

use std::sync::atomic::{AtomicU64, Ordering};

use super::exposition::Exposition;
use crate::control::foxglove_stats::FoxgloveStats;
use crate::control::ros2_stats::Ros2Stats;
use crate::http::state::AppState;

/// The ROS 2 bridge's counters (zero when it does not run) and the
/// recordings running.
pub(super) fn bridge_families(m: &mut Exposition, state: &AppState) {
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
    ros2_counters(m, stats);
    m.gauge(
        "jointd_recordings_running",
        "MCAP recordings being written.",
        "",
        crate::control::recordings::running(state.control()) as f64,
    );
}

/// The bridge's counters, 0 while it does not run.
fn ros2_counters(m: &mut Exposition, stats: Option<&Ros2Stats>) {
    type Field = fn(&Ros2Stats) -> &std::sync::atomic::AtomicU64;
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
}

/// The live Foxglove view's gauges and counters, 0 while it does not run.
/// What the SDK drops for a client whose queue is full it does not report
/// (it logs it, at most every 30 s): a slow client's losses are not here.
pub(super) fn foxglove_families(m: &mut Exposition, state: &AppState) {
    let stats = state.control().foxglove();
    m.gauge(
        "jointd_foxglove_enabled",
        "1 when the live Foxglove view runs (--foxglove).",
        "",
        if stats.is_some() { 1.0 } else { 0.0 },
    );
    m.gauge(
        "jointd_foxglove_clients",
        "Foxglove clients connected to the live view.",
        "",
        load(stats, |s| &s.clients),
    );
    m.counter(
        "jointd_foxglove_messages_total",
        "Messages logged to the live view while a client was subscribed to their channel.",
        "",
        load(stats, |s| &s.messages),
    );
    m.counter(
        "jointd_foxglove_lost_total",
        "Frames, setpoint writes and events the live view fell too far behind to see.",
        "",
        load(stats, |s| &s.lost),
    );
}

/// One of the live view's counters, 0 while it does not run.
fn load(stats: Option<&FoxgloveStats>, field: fn(&FoxgloveStats) -> &AtomicU64) -> f64 {
    stats.map_or(0, |s| field(s).load(Ordering::Relaxed)) as f64
}
