//! One reference to a joint (bus and id) for every front-end, how a device
//! id is checked, and how a joint named by bus and id or by hand and joint
//! name is resolved.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::{ControlError, ControlResult};
use super::Control;
use crate::bus::handle::{DeviceState, LinkState};
use crate::bus::{BusError, BusSnapshot};
use crate::protocol::{is_device_id, MAX_DEVICE_ID, MIN_DEVICE_ID};

/// A joint, by bus and id.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize, ToSchema)]
pub struct JointRef {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
}

/// A device id from a path or body: 1..=159, else 422 naming the range.
pub fn device_id(field: &str, id: i64) -> ControlResult<u8> {
    u8::try_from(id)
        .ok()
        .filter(|id| is_device_id(*id))
        .ok_or_else(|| {
            ControlError::out_of_range(
                field,
                id as f64,
                (f64::from(MIN_DEVICE_ID), f64::from(MAX_DEVICE_ID)),
                "",
            )
        })
}

/// The snapshot entry of a device, or 404; 503 when the bus is down (a bus
/// whose port is missing knows no device, and saying "unknown device" would
/// send the user scanning instead of plugging the adapter in).
pub fn known_device(snap: &BusSnapshot, id: u8) -> ControlResult<&DeviceState> {
    if let (None, LinkState::Down { reason, .. }) = (snap.devices.get(&id), &snap.link) {
        return Err(BusError::Down {
            bus: snap.name.clone(),
            reason: reason.clone(),
        }
        .into());
    }
    snap.devices.get(&id).ok_or_else(|| {
        ControlError::not_found(
            "unknown-device",
            format!(
                "device {id} is not known on bus {} (scan the bus to discover devices)",
                snap.name
            ),
        )
    })
}

/// A joint named by `bus` and `id`, or by `hand` and `joint` (its name in
/// a `[[hand]]`); `field` names it in errors (`joints[2]`).
pub fn resolve_joint(
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
            let hand_of = state
                .hands()
                .and_then(|store| store.hand(hand))
                .ok_or_else(|| {
                    ControlError::not_found("unknown-hand", format!("no hand named `{hand}`"))
                })?;
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
