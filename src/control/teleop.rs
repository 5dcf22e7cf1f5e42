//! What the teleoperation watchdog shares beyond one WebSocket connection:
//! the policy and hold-timeout bounds the config's `[watchdog]` default is
//! checked against, and the event every connection hears when a stream
//! stops. Here, not in `ws`, because the app state holds the default and
//! the WebSocket hub carries the events.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::control::joints::JointRef;

/// Shortest and longest hold timeouts a client (or the config) may declare.
pub const MIN_HOLD: Duration = Duration::from_millis(20);
pub const MAX_HOLD: Duration = Duration::from_millis(10_000);

/// What happens to a joint whose setpoint stream stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WatchdogPolicy {
    /// Freeze each joint where it is (target := measured angle).
    #[default]
    Hold,
    /// Disable each joint.
    Disable,
}

/// The config's `[watchdog]`: armed for every client that streams setpoints
/// (`hold_timeout_ms` 0: only clients that ask get one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WatchdogDefault {
    pub hold_timeout_ms: u64,
    pub policy: WatchdogPolicy,
}

impl Default for WatchdogDefault {
    fn default() -> Self {
        Self {
            hold_timeout_ms: 0,
            policy: WatchdogPolicy::Hold,
        }
    }
}

/// Sent to every connection when one connection's stream stopped.
#[derive(Debug, Clone, Serialize)]
pub struct WatchdogEvent {
    /// Always `"watchdog"`.
    pub event: &'static str,
    /// The connection whose stream stopped.
    pub client: u64,
    pub policy: WatchdogPolicy,
    /// `why`: `timeout` or `closed`.
    pub why: &'static str,
    pub joints: Vec<JointRef>,
}

/// What the watchdog does to joints `ids` of `bus` whose stream stopped
/// (WebSocket clients and the ROS 2 bridge alike): hold each where it is
/// measured, or disable them. Held in position mode, a joint keeps its
/// speed limit; in speed mode the speed slot *is* the motion, so it is 0.
pub(crate) async fn apply_policy(
    bus: &crate::bus::BusHandle,
    ids: Vec<u8>,
    policy: WatchdogPolicy,
) {
    match policy {
        WatchdogPolicy::Disable => {
            if let Err(e) = bus.disable(crate::bus::Targets::Ids(ids)).await {
                tracing::error!(bus = bus.name(), error = %e, "watchdog could not disable joints");
            }
        }
        WatchdogPolicy::Hold => {
            let snap = bus.snapshot();
            let holds: Vec<(u8, crate::bus::Setpoint)> = ids
                .iter()
                .filter_map(|id| snap.devices.get(id))
                .filter_map(|d| {
                    let spd_ref = match d.mode {
                        Some(crate::protocol::values::CtrlMode::Speed) => 0,
                        _ => d.target_sent?.spd_ref,
                    };
                    Some((
                        d.dev_id,
                        crate::bus::Setpoint {
                            pos_ref: crate::control::device::measured_angle_raw(d)?,
                            spd_ref,
                        },
                    ))
                })
                .collect();
            bus.set_targets_as(&holds, crate::bus::Source::Hold);
        }
    }
}
