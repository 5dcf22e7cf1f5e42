//! Going to a saved pose: a hand's pose (joint name → angle) turned into a
//! move of that hand's joints, started like any move (checked whole,
//! admitted under each joint's motion epoch).

use super::error::{ControlError, ControlResult};
use super::moves::{self, MoveJoint, MoveRequest, MoveView};
use crate::control::lookup::unknown_hand;
use crate::control::state::Control;
use crate::motion::Method;

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
