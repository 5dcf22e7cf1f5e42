//! `joint_commands` (a `sensor_msgs/msg/JointState` with positions and
//! optional velocities, matched by name: the convention of
//! `topic_based_ros2_control`) turned into setpoints through the same path
//! as REST and WebSocket targets: each joint known on the bus, enabled, its
//! calibrated range, soft limits and speed limit. A command with one bad
//! joint is refused whole: nothing of it is applied.

use crate::bus::{BusHandle, Setpoint};
use crate::http::state::AppState;
use crate::http::targets::{setpoint, TargetRequest};
use crate::http::telemetry::is_enabled;
use crate::protocol::units;
use crate::record::cdr::JointState;

/// Below this, a velocity is no speed limit (a controller at rest sends 0).
const MIN_SPEED_DPS: f64 = 0.5;

/// The setpoints `cmd` asks of `bus`, or why it is refused.
pub(crate) fn setpoints(
    state: &AppState,
    bus: &BusHandle,
    cmd: &JointState,
) -> Result<Vec<(u8, Setpoint)>, String> {
    if cmd.name.is_empty() {
        return Err("no joint named".into());
    }
    if cmd.position.len() != cmd.name.len() {
        return Err(format!(
            "{} names but {} positions (a position per joint is required)",
            cmd.name.len(),
            cmd.position.len()
        ));
    }
    if !cmd.velocity.is_empty() && cmd.velocity.len() != cmd.name.len() {
        return Err(format!(
            "{} names but {} velocities (none, or one per joint)",
            cmd.name.len(),
            cmd.velocity.len()
        ));
    }
    let snap = bus.snapshot();
    let label = state.joint_labeler();
    let mut out: Vec<(u8, Setpoint)> = Vec::with_capacity(cmd.name.len());
    for (i, name) in cmd.name.iter().enumerate() {
        let dev = snap
            .devices
            .values()
            .find(|d| label(bus.name(), d.dev_id).0 == *name)
            .ok_or_else(|| format!("no joint named `{name}` on bus `{}`", bus.name()))?;
        if out.iter().any(|(id, _)| *id == dev.dev_id) {
            return Err(format!("joint `{name}` is named twice"));
        }
        if dev
            .info01
            .as_ref()
            .is_some_and(|(info, _)| !is_enabled(info))
        {
            return Err(format!("joint `{name}` is not enabled"));
        }
        let rad = cmd.position[i];
        let dps = cmd.velocity.get(i).map(|v| v.to_degrees().abs());
        if !rad.is_finite() || dps.is_some_and(|v| !v.is_finite()) {
            return Err(format!("joint `{name}`: not a finite number"));
        }
        let req = TargetRequest {
            position_deg: Some(rad.to_degrees()),
            speed_rpm: dps
                .filter(|v| *v >= MIN_SPEED_DPS)
                .map(|v| v / units::output_deg_per_s(1.0)),
        };
        let cal = state.calibration(bus.name(), dev.dev_id);
        let limits = state.limits(bus.name(), dev.dev_id);
        let sp = setpoint(dev, &limits, &cal, &req, &format!("{name}."))
            .map_err(|e| format!("joint `{name}`: {}", e.problem.detail))?;
        out.push((dev.dev_id, sp));
    }
    Ok(out)
}
