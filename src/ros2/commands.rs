//! `joint_commands` (a `sensor_msgs/msg/JointState` matched by name: the
//! convention of `topic_based_ros2_control`) turned into setpoints through
//! the same path as REST and WebSocket targets: each joint known on the
//! bus, enabled, its calibrated range, soft limits and speed limit. Per
//! message: positions (with velocities as their speed limits), or
//! velocities only (rad/s at the output shaft: [`velocity::request`] makes
//! each a target toward the joint's soft limit at that speed). A command
//! with one bad joint is refused whole: nothing of it is applied.
//! [`Refused`] says why, and under which cause (what `/rosout` is
//! throttled by).

use crate::control::batch::BatchItem;
use crate::control::error::ControlError;
use crate::control::joints::known_device;
use crate::control::targets::TargetRequest;
use crate::control::velocity;
use crate::control::Control;
use crate::control::JointRef;
use crate::record::joint_states::Scope;
use crate::rosmsg::JointState;

/// Why a command (or trajectory) was refused whole: its cause, a short
/// name (the control core's problem name where it refused), and the words.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Refused {
    pub cause: String,
    pub why: String,
}

impl Refused {
    pub(crate) fn new(cause: &str, why: impl Into<String>) -> Self {
        Self {
            cause: cause.to_owned(),
            why: why.into(),
        }
    }
}

impl From<ControlError> for Refused {
    fn from(e: ControlError) -> Self {
        let cause = match &e {
            ControlError::Invalid { kind, .. } => kind.name(),
            ControlError::NotFound { kind, .. } | ControlError::Conflict { kind, .. } => kind,
            ControlError::Bus(_) => "bus",
            _ => "internal",
        };
        Self::new(cause, e.to_string())
    }
}

/// The joints of `scope` a name may mean: (bus, id).
fn candidates(state: &Control, scope: &Scope) -> Vec<(String, u8)> {
    match scope {
        Scope::Bus(bus) => state
            .reader(bus)
            .map(|b| {
                b.snapshot()
                    .devices
                    .keys()
                    .map(|id| (bus.clone(), *id))
                    .collect()
            })
            .unwrap_or_default(),
        Scope::Hand { joints, .. } => joints.clone(),
    }
}

/// The joints of `scope` named `names` (as `joint_states` names them), in
/// order; or the first name that is none of them.
pub(crate) fn joints_named(
    state: &std::sync::Arc<Control>,
    scope: &Scope,
    names: &[String],
) -> Result<Vec<JointRef>, Refused> {
    let label = state.joint_labeler();
    let candidates = candidates(state, scope);
    names
        .iter()
        .map(|name| {
            candidates
                .iter()
                .find(|(b, id)| label(b, *id).0 == *name)
                .map(|(bus, id)| JointRef {
                    bus: bus.clone(),
                    id: *id,
                })
                .ok_or_else(|| {
                    Refused::new("unknown-joint", format!("no joint named `{name}` here"))
                })
        })
        .collect()
}

/// The targets `cmd` asks of the joints of `scope` (a bus, or a hand on
/// one or more buses), each with its joint, for the core's teleop step
/// (which checks them whole); or why it is refused.
pub(crate) fn targets(
    state: &std::sync::Arc<Control>,
    scope: &Scope,
    cmd: &JointState,
) -> Result<Vec<BatchItem>, Refused> {
    check_shape(cmd).map_err(|why| Refused::new("malformed", why))?;
    let joints = joints_named(state, scope, &cmd.name)?;
    let mut items = Vec::with_capacity(cmd.name.len());
    for (i, (name, joint)) in cmd.name.iter().zip(joints).enumerate() {
        let field = format!("{name}.");
        let request = if cmd.position.is_empty() {
            velocity_request(state, &joint.bus, joint.id, cmd.velocity[i], &field)?
        } else {
            position_request(name, cmd.position[i], cmd.velocity.get(i).copied())?
        };
        items.push(BatchItem {
            joint,
            request,
            field,
        });
    }
    Ok(items)
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
fn position_request(name: &str, rad: f64, rad_s: Option<f64>) -> Result<TargetRequest, Refused> {
    let dps = rad_s.map(|v| v.to_degrees().abs());
    if !rad.is_finite() || dps.is_some_and(|v| !v.is_finite()) {
        return Err(Refused::new(
            "not-finite",
            format!("joint `{name}`: not a finite number"),
        ));
    }
    Ok(TargetRequest {
        position_deg: Some(rad.to_degrees()),
        // A controller at rest sends 0: no speed limit then.
        speed_dps: dps.filter(|v| *v >= velocity::MIN_SPEED_DPS),
    })
}

/// A velocity alone (rad/s): a target toward the soft limit at that speed.
fn velocity_request(
    state: &Control,
    bus: &str,
    id: u8,
    rad_s: f64,
    field: &str,
) -> Result<TargetRequest, Refused> {
    let snap = state.reader(bus)?.snapshot();
    let dev = known_device(&snap, id)?;
    let limits = state.limits(bus, id);
    let cal = state.calibration(bus, id);
    velocity::request(dev, &limits, &cal, rad_s.to_degrees(), field).map_err(|e| {
        let words = format!("joint `{}`: {e}", field.trim_end_matches('.'));
        Refused::from(e.with_detail(words))
    })
}
