//! One reference to a joint (bus and id) for every front-end, how a device
//! id is checked, and a device known on its bus; no lookup of names here
//! (that is [`super::lookup`], above the core's state).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::{ControlError, ControlResult};
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
