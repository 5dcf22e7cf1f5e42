//! `joint_commands` (a `sensor_msgs/msg/JointState` with positions and
//! optional velocities, matched by name: the convention of
//! `topic_based_ros2_control`) turned into setpoints through the same path
//! as REST and WebSocket targets: each joint known on the bus, enabled, its
//! calibrated range, soft limits and speed limit. A command with one bad
//! joint is refused whole: nothing of it is applied.

use crate::bus::{BusHandle, Setpoint};
use crate::control::targets::{setpoint, TargetRequest};
use crate::control::Control;
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
    let mut out: Vec<BusTargets> = Vec::new();
    for (i, name) in cmd.name.iter().enumerate() {
        let (bus_name, id) = candidates
            .iter()
            .find(|(b, id)| label(b, *id).0 == *name)
            .ok_or_else(|| format!("no joint named `{name}` here"))?;
        let bus = state
            .bus(bus_name)
            .map_err(|_| format!("joint `{name}`: no bus `{bus_name}`"))?;
        let snap = bus.snapshot();
        let dev = snap
            .devices
            .get(id)
            .ok_or_else(|| format!("joint `{name}` has not been seen on bus `{bus_name}`"))?;
        let group = match out.iter().position(|(b, _)| b.name() == bus_name) {
            Some(k) => k,
            None => {
                out.push((bus.clone(), Vec::new()));
                out.len() - 1
            }
        };
        if out[group].1.iter().any(|(seen, _)| seen == id) {
            return Err(format!("joint `{name}` is named twice"));
        }
        if !bus.grant(*id).enabled {
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
        let cal = state.calibration(bus_name, *id);
        let limits = state.limits(bus_name, *id);
        let sp = setpoint(dev, &limits, &cal, &req, &format!("{name}."))
            .map_err(|e| format!("joint `{name}`: {e}"))?;
        out[group].1.push((*id, sp));
    }
    Ok(out)
}
