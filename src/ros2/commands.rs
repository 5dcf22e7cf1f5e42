//! `joint_commands` (a `sensor_msgs/msg/JointState` with positions and
//! optional velocities, matched by name: the convention of
//! `topic_based_ros2_control`) turned into setpoints through the same path
//! as REST and WebSocket targets: each joint known on the bus, enabled, its
//! calibrated range, soft limits and speed limit. A command with one bad
//! joint is refused whole: nothing of it is applied.

use crate::bus::{BusHandle, Setpoint};
use crate::control::batch::{self, BatchItem};
use crate::control::targets::TargetRequest;
use crate::control::Control;
use crate::control::JointRef;
use crate::protocol::units;
use crate::record::cdr::JointState;
use crate::record::joint_states::Scope;

/// Below this, a velocity is no speed limit (a controller at rest sends 0).
const MIN_SPEED_DPS: f64 = 0.5;

/// Targets for joints of one bus.
pub(crate) type BusTargets = (BusHandle, Vec<(u8, Setpoint)>);

/// The setpoints `cmd` asks of the joints of `scope` (a bus, or a hand on
/// one or more buses), grouped by bus; or why it is refused.
pub(crate) fn setpoints(
    state: &std::sync::Arc<Control>,
    scope: &Scope,
    cmd: &JointState,
) -> Result<Vec<BusTargets>, String> {
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
        let rad = cmd.position[i];
        let dps = cmd.velocity.get(i).map(|v| v.to_degrees().abs());
        if !rad.is_finite() || dps.is_some_and(|v| !v.is_finite()) {
            return Err(format!("joint `{name}`: not a finite number"));
        }
        items.push(BatchItem {
            joint: JointRef {
                bus: bus.clone(),
                id: *id,
            },
            request: TargetRequest {
                position_deg: Some(rad.to_degrees()),
                speed_rpm: dps
                    .filter(|v| *v >= MIN_SPEED_DPS)
                    .map(|v| v / units::output_deg_per_s(1.0)),
            },
            field: format!("{name}."),
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
