//! A hand's saved poses (joint name → angle, in the joints' calibrated
//! frames): read, saved (checked against each joint's calibrated range and
//! soft limits, or taken from where the hand is), deleted, and gone to as
//! a move of the hand's joints, started like any move (checked whole,
//! admitted under each joint's motion epoch).

use std::collections::BTreeMap;

use super::device::commanded_or_measured_raw;
use super::error::{ControlError, ControlResult};
use super::moves::{self, MoveJoint, MoveRequest, MoveView};
use crate::control::lookup::unknown_hand;
use crate::control::state::Control;
use crate::hands::{Hand, Pose, StateStore};
use crate::motion::Method;
use crate::protocol::units;

/// Longest pose name.
pub(crate) const MAX_POSE_NAME: usize = 64;

/// What a saved pose is made of.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum PoseSource {
    /// Angles by joint name (any subset of the hand's joints).
    Angles(BTreeMap<String, f64>),
    /// Where every joint of the hand is now: its last target, else its angle.
    Current,
}

/// How a pose is reached: a move's timing and shape.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct PoseTiming {
    pub(crate) duration_ms: Option<f64>,
    pub(crate) max_velocity_dps: Option<f64>,
    pub(crate) max_acceleration_dps2: Option<f64>,
    pub(crate) method: Option<Method>,
}

/// Starts the move of hand `hand` to its pose `name`.
pub(crate) async fn go(
    control: &Control,
    hand: &str,
    name: &str,
    timing: PoseTiming,
) -> ControlResult<MoveView> {
    let hand_of = control.hand(hand)?;
    let store = control.hands().ok_or_else(|| unknown_hand(hand))?;
    let pose = store.pose(hand, name).ok_or_else(|| {
        ControlError::not_found(
            "unknown-pose",
            format!("hand `{hand}` has no pose named `{name}`"),
        )
    })?;
    let joints = pose
        .iter()
        .filter_map(|(joint, deg)| {
            hand_of.joint(joint).map(|j| MoveJoint {
                bus: Some(j.bus.clone()),
                id: Some(i64::from(j.id)),
                hand: None,
                joint: None,
                position_deg: Some(*deg),
            })
        })
        .collect();
    let request = MoveRequest {
        joints,
        duration_ms: timing.duration_ms,
        max_velocity_dps: timing.max_velocity_dps,
        max_acceleration_dps2: timing.max_acceleration_dps2,
        method: timing.method,
        waypoints: None,
    };
    moves::start(control, &request).await
}

/// Hand `hand`'s pose `name`.
pub(crate) fn get(control: &Control, hand: &str, name: &str) -> ControlResult<Pose> {
    let (store, _) = hand_and_store(control, hand)?;
    saved(store, hand, name)
}

/// Saves hand `hand`'s pose `name` (replacing one of that name) in the
/// state file, before it answers: it survives a restart.
pub(crate) fn save(
    control: &Control,
    hand: &str,
    name: &str,
    source: PoseSource,
) -> ControlResult<Pose> {
    let (store, hand_of) = hand_and_store(control, hand)?;
    check_name(name)?;
    let pose = match source {
        PoseSource::Angles(positions) => checked(control, hand_of, positions)?,
        PoseSource::Current => current(control, hand_of)?,
    };
    store
        .put(hand, name, pose.clone())
        .map_err(|e| ControlError::state_unwritable(format!("{e}; the pose was not saved")))?;
    tracing::info!(hand, pose = name, joints = pose.len(), "pose saved");
    Ok(pose)
}

/// Deletes hand `hand`'s pose `name` from the state file; the pose as it was.
pub(crate) fn delete(control: &Control, hand: &str, name: &str) -> ControlResult<Pose> {
    let (store, _) = hand_and_store(control, hand)?;
    let pose = saved(store, hand, name)?;
    store
        .delete(hand, name)
        .map_err(|e| ControlError::state_unwritable(format!("{e}; the pose was not deleted")))?;
    Ok(pose)
}

fn hand_and_store<'a>(
    control: &'a Control,
    hand: &str,
) -> ControlResult<(&'a StateStore, &'a Hand)> {
    let hand_of = control.hand(hand)?;
    let store = control.hands().ok_or_else(|| unknown_hand(hand))?;
    Ok((store, hand_of))
}

fn saved(store: &StateStore, hand: &str, name: &str) -> ControlResult<Pose> {
    store.pose(hand, name).ok_or_else(|| {
        ControlError::not_found(
            "unknown-pose",
            format!("hand `{hand}` has no pose named `{name}`"),
        )
    })
}

fn check_name(name: &str) -> ControlResult<()> {
    let ok = !name.is_empty()
        && name.len() <= MAX_POSE_NAME
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        return Ok(());
    }
    Err(ControlError::invalid(
        "name",
        format!("pose name `{name}`: 1..={MAX_POSE_NAME} letters, digits, `_` or `-`"),
    ))
}

/// Angles given by joint name (calibrated frame): each joint of the hand,
/// a finite number within its calibrated range and soft limits.
fn checked(
    control: &Control,
    hand: &Hand,
    positions: BTreeMap<String, f64>,
) -> ControlResult<Pose> {
    if positions.is_empty() {
        return Err(ControlError::invalid(
            "positions_deg",
            "positions_deg is empty",
        ));
    }
    for (name, deg) in &positions {
        let field = format!("positions_deg.{name}");
        let joint = hand.joint(name).ok_or_else(|| {
            let names: Vec<&str> = hand.joints.iter().map(|j| j.name.as_str()).collect();
            ControlError::invalid(
                &field,
                format!(
                    "hand `{}` has no joint `{name}` (it has {})",
                    hand.name,
                    names.join(", ")
                ),
            )
        })?;
        if !deg.is_finite() {
            return Err(ControlError::invalid(&field, "not a finite number"));
        }
        let who = format!("joint `{name}` ({} on bus `{}`)", joint.id, joint.bus);
        let cal = control.calibration(&joint.bus, joint.id);
        control
            .limits(&joint.bus, joint.id)
            .check_joint_position(&cal, &field, *deg, &who)?;
    }
    Ok(positions)
}

/// Where every joint of the hand is now: its last target, else its angle.
fn current(control: &Control, hand: &Hand) -> ControlResult<Pose> {
    let mut pose = Pose::new();
    for j in &hand.joints {
        let snap = control.bus(&j.bus)?.snapshot();
        let raw = snap
            .devices
            .get(&j.id)
            .and_then(commanded_or_measured_raw)
            .ok_or_else(|| {
                ControlError::conflict(
                    "no-position",
                    "Position unknown",
                    format!(
                        "joint `{}` ({} on bus `{}`) has not reported its angle",
                        j.name, j.id, j.bus
                    ),
                )
            })?;
        let cal = control.calibration(&j.bus, j.id);
        pose.insert(j.name.clone(), cal.to_joint(units::angle_deg(raw)));
    }
    Ok(pose)
}
