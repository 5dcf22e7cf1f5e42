//! Finding what a front-end names: a hand by its name, a joint by bus and
//! id or by hand and joint name. One answer (and one refusal) for REST,
//! WebSocket, ROS 2 and the jobs alike.

use super::error::{ControlError, ControlResult};
use super::joints::{device_id, JointRef};
use super::state::Control;
use crate::hands::Hand;

/// 404 `unknown-hand`, naming it.
pub(crate) fn unknown_hand(name: &str) -> ControlError {
    ControlError::not_found("unknown-hand", format!("no hand named `{name}`"))
}

impl Control {
    /// The hand named `name` in the config, or 404 naming it.
    pub fn hand(&self, name: &str) -> ControlResult<&Hand> {
        self.hands()
            .and_then(|store| store.hand(name))
            .ok_or_else(|| unknown_hand(name))
    }
}

/// A joint named by `bus` and `id`, or by `hand` and `joint` (its name in
/// a `[[hand]]`); `field` names it in errors (`joints[2]`).
pub(crate) fn resolve_joint(
    state: &Control,
    field: &str,
    bus: Option<&str>,
    id: Option<i64>,
    hand: Option<&str>,
    joint: Option<&str>,
) -> ControlResult<JointRef> {
    match (bus, id, hand, joint) {
        (Some(bus), Some(id), None, None) => {
            state.bus(bus)?;
            Ok(JointRef {
                bus: bus.to_owned(),
                id: device_id(&format!("{field}.id"), id)?,
            })
        }
        (None, None, Some(hand), Some(name)) => {
            let hand_of = state.hand(hand)?;
            let joint = hand_of.joint(name).ok_or_else(|| {
                ControlError::invalid(
                    &format!("{field}.joint"),
                    format!("hand `{hand}` has no joint `{name}`"),
                )
            })?;
            Ok(JointRef {
                bus: joint.bus.clone(),
                id: joint.id,
            })
        }
        _ => Err(ControlError::invalid(
            field,
            "name a joint by `bus` and `id`, or by `hand` and `joint`",
        )),
    }
}
