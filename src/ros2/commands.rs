//! `joint_commands` (a `sensor_msgs/msg/JointState` matched by name: the
//! convention of `topic_based_ros2_control`) turned into setpoints through
//! the same path as REST and WebSocket targets: each joint known on the
//! bus, enabled, its calibrated range, soft limits and speed limit. Per
//! message: positions (with velocities as their speed limits), or
//! velocities only (rad/s at the output shaft: [`velocity::request`] makes
//! each a target toward the joint's soft limit at that speed). A command
//! with one bad joint is refused whole: nothing of it is applied.

use crate::bus::{BusHandle, Setpoint};
use crate::control::batch::{self, BatchItem};
use crate::control::joints::known_device;
use crate::control::targets::TargetRequest;
use crate::control::velocity;
use crate::control::Control;
use crate::control::JointRef;
use crate::protocol::units;
use crate::record::cdr::JointState;
use crate::record::joint_states::Scope;

/// Targets for joints of one bus.
pub(crate) type BusTargets = (BusHandle, Vec<(u8, Setpoint)>);

/// The setpoints `cmd` asks of the joints of `scope` (a bus, or a hand on
/// one or more buses), grouped by bus; or why it is refused.
pub(crate) fn setpoints(
    state: &std::sync::Arc<Control>,
    scope: &Scope,
    cmd: &JointState,
) -> Result<Vec<BusTargets>, String> {
    check_shape(cmd)?;
    let label = state.joint_labeler();
    let candidates: Vec<(String, u8)> = match scope {
        Scope::Bus(bus) => state
            .bus(bus)
            .map(|b| {
                b.snapshot()
                    .devices
                    .keys()
                    .map(|id| (bus.clone(), *id))
                    .collect()
            })
            .unwrap_or_default(),
        Scope::Hand { joints, .. } => joints.clone(),
    };
    let mut items = Vec::with_capacity(cmd.name.len());
    for (i, name) in cmd.name.iter().enumerate() {
        let (bus, id) = candidates
            .iter()
            .find(|(b, id)| label(b, *id).0 == *name)
            .ok_or_else(|| format!("no joint named `{name}` here"))?;
        let field = format!("{name}.");
        let request = if cmd.position.is_empty() {
            velocity_request(state, bus, *id, cmd.velocity[i], &field)?
        } else {
            position_request(name, cmd.position[i], cmd.velocity.get(i).copied())?
        };
        items.push(BatchItem {
            joint: JointRef {
                bus: bus.clone(),
                id: *id,
            },
            request,
            field,
        });
    }
    let per_bus = batch::resolve(state, &items).map_err(|e| e.to_string())?;
    per_bus
        .into_iter()
        .map(|(name, targets)| {
            let bus = state.bus(&name).map_err(|e| e.to_string())?.clone();
            Ok((bus, targets))
        })
        .collect()
}

/// Whether a command asks for velocities only.
pub(crate) fn by_velocity(cmd: &JointState) -> bool {
    cmd.position.is_empty() && !cmd.velocity.is_empty()
}

/// A name per joint, and positions, velocities or both: each none or one
/// per joint.
fn check_shape(cmd: &JointState) -> Result<(), String> {
    let n = cmd.name.len();
    if n == 0 {
        return Err("no joint named".into());
    }
    for (what, len) in [
        ("positions", cmd.position.len()),
        ("velocities", cmd.velocity.len()),
    ] {
        if len != 0 && len != n {
            return Err(format!(
                "{n} names but {len} {what} (none, or one per joint)"
            ));
        }
    }
    if cmd.position.is_empty() && cmd.velocity.is_empty() {
        return Err("neither positions nor velocities (give either, or both)".into());
    }
    Ok(())
}

/// A position (rad), its velocity (rad/s) if any as the speed limit.
fn position_request(name: &str, rad: f64, rad_s: Option<f64>) -> Result<TargetRequest, String> {
    let dps = rad_s.map(|v| v.to_degrees().abs());
    if !rad.is_finite() || dps.is_some_and(|v| !v.is_finite()) {
        return Err(format!("joint `{name}`: not a finite number"));
    }
    Ok(TargetRequest {
        position_deg: Some(rad.to_degrees()),
        // A controller at rest sends 0: no speed limit then.
        speed_rpm: dps
            .filter(|v| *v >= velocity::MIN_SPEED_DPS)
            .map(|v| v / units::output_deg_per_s(1.0)),
    })
}

/// A velocity alone (rad/s): a target toward the soft limit at that speed.
fn velocity_request(
    state: &Control,
    bus: &str,
    id: u8,
    rad_s: f64,
    field: &str,
) -> Result<TargetRequest, String> {
    let snap = state.bus(bus).map_err(|e| e.to_string())?.snapshot();
    let dev = known_device(&snap, id).map_err(|e| e.to_string())?;
    let limits = state.limits(bus, id);
    let cal = state.calibration(bus, id);
    velocity::request(dev, &limits, &cal, rad_s.to_degrees(), field)
        .map_err(|e| format!("joint `{}`: {e}", field.trim_end_matches('.')))
}
