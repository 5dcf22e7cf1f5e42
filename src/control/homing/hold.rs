//! Holding a homed or aborted joint where it is: speed 0 on the wire, then
//! position mode; and the guard that writes speed 0 if a task unwinds
//! mid-search.

use crate::bus::{BusHandle, Setpoint, Source};
use crate::control::device::measured_angle_raw;
use crate::control::targets::wait_on_wire;
use crate::protocol::CtrlMode;

/// Writes speed 0 (holding where the joint is) if the task leaves the
/// search without [`hold_here`] having done it: a panic unwinding.
pub(super) struct SpeedZero {
    pub(super) bus: BusHandle,
    pub(super) id: u8,
    pub(super) armed: bool,
}

impl Drop for SpeedZero {
    fn drop(&mut self) {
        if self.armed {
            tracing::error!(
                bus = self.bus.name(),
                id = self.id,
                "homing ended mid-search: speed 0 written"
            );
            speed_zero(&self.bus, self.id);
        }
    }
}

/// Speed 0, the position target where the joint is; the setpoint's
/// sequence number (to wait for it on the wire), `None` when the joint's
/// angle is not known (nothing written).
fn speed_zero(bus: &BusHandle, id: u8) -> Option<u64> {
    let here = bus
        .snapshot()
        .devices
        .get(&id)
        .and_then(measured_angle_raw)?;
    Some(bus.set_targets_as(
        &[(
            id,
            Setpoint {
                pos_ref: here,
                spd_ref: 0,
            },
        )],
        Source::Homing,
    ))
}

/// Writes speed 0 and waits (briefly) until it is on the wire; false if it
/// was not seen there.
pub(super) async fn speed_zero_on_wire(bus: &BusHandle, id: u8) -> bool {
    match speed_zero(bus, id) {
        Some(seq) => wait_on_wire(bus, seq).await,
        None => false,
    }
}

/// Stops pushing and goes back to position mode: speed 0 (holding where
/// the joint is) on the wire first, then the mode. After an e-stop too:
/// speed 0 moves nothing, and a disabled joint keeps no speed for later.
pub(super) async fn hold_here(bus: &BusHandle, id: u8) {
    if !speed_zero_on_wire(bus, id).await {
        tracing::warn!(
            bus = bus.name(),
            id,
            "homing: speed 0 not seen on the wire before leaving speed mode"
        );
    }
    if let Err(e) = bus.set_mode(id, CtrlMode::Position).await {
        tracing::warn!(bus = bus.name(), id, error = %e, "homing: could not switch back to position mode");
    }
}
