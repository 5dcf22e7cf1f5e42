//! One batch resolver for the teleop front-ends (WebSocket setpoints, ROS 2
//! joint commands): targets for joints each front-end has named in its own
//! way, checked whole (each joint once, known on its bus, enabled by the
//! daemon, its calibrated range, soft limits and speed limit) and grouped
//! by bus. One bad target refuses the batch: nothing of it is applied.

use std::collections::BTreeMap;

use super::error::{ControlError, ControlResult};
use super::joints::known_device;
use super::joints::JointRef;
use super::state::Control;
use super::targets::{setpoint, TargetRequest};
use crate::bus::Setpoint;

/// One target of a batch, its joint already named.
#[derive(Debug, Clone)]
pub(crate) struct BatchItem {
    pub(crate) joint: JointRef,
    pub(crate) request: TargetRequest,
    /// How the front-end names this target in errors (`targets[2].`, `thumb.`).
    pub(crate) field: String,
}

/// Setpoints by bus name, each bus's in the batch's order.
pub(crate) type PerBus = BTreeMap<String, Vec<(u8, Setpoint)>>;

/// Checks every item, then groups them by bus.
pub(crate) fn resolve(control: &Control, items: &[BatchItem]) -> ControlResult<PerBus> {
    let mut per_bus = PerBus::new();
    let mut snapshots = BTreeMap::new();
    for item in items {
        let JointRef { bus: name, id } = &item.joint;
        let bus = control.bus(name)?;
        let snap = snapshots
            .entry(name.clone())
            .or_insert_with(|| bus.snapshot());
        let dev = known_device(snap, *id)?;
        let list = per_bus.entry(name.clone()).or_default();
        if list.iter().any(|(seen, _)| seen == id) {
            return Err(ControlError::duplicate(
                &item.field,
                format!("joint {id} of bus {name} appears twice in one batch"),
            ));
        }
        // The bus's motion authority, an atomic read: no bus round trip at
        // teleoperation rates, and never a snapshot that lags an e-stop.
        if !bus.grant(*id).enabled {
            return Err(ControlError::conflict(
                "not-enabled",
                "Device not enabled",
                format!("joint {id} of bus {name} is not enabled (enable it first)"),
            )
            .with_field(item.field.trim_end_matches('.')));
        }
        let limits = control.limits(name, *id);
        let cal = control.calibration(name, *id);
        list.push((
            *id,
            setpoint(dev, &limits, &cal, &item.request, &item.field)?,
        ));
    }
    Ok(per_bus)
}
