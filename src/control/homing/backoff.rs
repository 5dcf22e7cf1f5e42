//! Off the stop once it is found: slowly, in position mode, never outside
//! the soft limits, and not at all after an e-stop.

use std::time::Duration;

use tokio::sync::broadcast;

use super::request::Plan;
use super::search::aborted_by_event;
use crate::bus::handle::BusEvent;
use crate::bus::{BusHandle, Setpoint, Source};
use crate::control::device::{firmware_of, measured_angle_raw};
use crate::control::limits::JointLimits;
use crate::protocol::units;

/// How long the back-off may take before the job ends anyway.
const BACKOFF_WAIT: Duration = Duration::from_secs(5);
/// Close enough to the back-off goal, degrees.
const BACKOFF_TOLERANCE_DEG: f64 = 0.5;
/// Speed limit of the back-off, rotor rpm (≈ 10 °/s at the output).
const BACKOFF_RPM: f64 = 1000.0;

/// Off the stop by `backoff_deg`, slowly, in position mode; waits (a
/// little) until it is there. An e-stop meanwhile leaves it where it is;
/// a goal outside the soft limits is not sent.
pub(super) async fn back_off(
    bus: &BusHandle,
    id: u8,
    plan: &Plan,
    soft: &JointLimits,
    stop_deg: f64,
    events: &mut broadcast::Receiver<BusEvent>,
) {
    if plan.backoff_deg == 0.0 || aborted_by_event(bus, events).is_err() {
        return;
    }
    let goal = stop_deg - plan.direction.sign() * plan.backoff_deg;
    if goal < soft.min_deg || goal > soft.max_deg {
        tracing::warn!(
            bus = bus.name(),
            id,
            goal,
            "homing: the back-off goal is outside the soft limits; the joint stays at its stop"
        );
        return;
    }
    let snap = bus.snapshot();
    let fw = snap.devices.get(&id).map(firmware_of).unwrap_or_default();
    let (Ok(pos_ref), Ok(spd_ref)) = (
        units::angle_to_raw(goal),
        units::speed_limit_to_raw(BACKOFF_RPM, fw),
    ) else {
        return;
    };
    bus.set_targets_as(&[(id, Setpoint { pos_ref, spd_ref })], Source::Homing);
    let mut watch = bus.watch();
    let reached = watch.wait_for(|s| {
        s.devices
            .get(&id)
            .and_then(measured_angle_raw)
            .is_some_and(|a| (units::angle_deg(a) - goal).abs() < BACKOFF_TOLERANCE_DEG)
    });
    let _ = tokio::time::timeout(BACKOFF_WAIT, reached).await;
}
