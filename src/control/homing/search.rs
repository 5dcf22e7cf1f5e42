//! The search itself: speed mode towards the stop, under the epoch the
//! job was admitted with, until the samples say the joint stalls there
//! ([`super::stall`]), a bound is reached, or anything ends the joint's
//! part (an e-stop, a revoked epoch, a fault, the joint offline).

use std::time::{Duration, Instant};

use tokio::sync::broadcast;

use super::hold::speed_zero_on_wire;
use super::request::Plan;
use super::stall::{Bound, Sample, StallWatch};
use crate::bus::authority::{Epoch, Revoked};
use crate::bus::handle::{BusEvent, DeviceState};
use crate::bus::{BusHandle, Setpoint, Source};
use crate::control::device::{firmware_of, is_enabled, measured_angle_raw};
use crate::control::limits::JointLimits;
use crate::protocol::status::{active_fault, fault_name, fsm};
use crate::protocol::units;
use crate::protocol::CtrlMode;

/// Why a search ended without finding the stop.
pub(super) enum Ended {
    Failed(String),
    Aborted(String),
}

/// A joint of a homing job and the motion epoch it was admitted under.
#[derive(Debug, Clone, Copy)]
pub(super) struct Admitted {
    pub(super) id: u8,
    pub(super) epoch: Epoch,
}

/// Speed mode towards the stop until the joint stalls there; its angle.
/// Ends (failed) at the soft limit or after `max_travel_deg`.
pub(super) async fn search(
    bus: &BusHandle,
    joint: Admitted,
    plan: &Plan,
    soft: &JointLimits,
    events: &mut broadcast::Receiver<BusEvent>,
) -> Result<f64, Ended> {
    let id = joint.id;
    let snap = bus.snapshot();
    let dev = snap
        .devices
        .get(&id)
        .ok_or_else(|| Ended::Failed("the joint is gone".into()))?;
    let here = measured_angle_raw(dev)
        .ok_or_else(|| Ended::Failed("the joint's angle is not known".into()))?;
    let start_deg = units::angle_deg(here);
    let bound = Bound::new(plan, soft, start_deg);
    if bound.reached(plan.direction, start_deg, plan.speed_dps) {
        return Err(Ended::Failed(bound.failure(start_deg)));
    }
    let rpm = plan.direction.sign() * plan.speed_dps / units::output_deg_per_s(1.0);
    let spd_ref = units::speed_to_raw(rpm, firmware_of(dev))
        .map_err(|e| Ended::Failed(format!("speed_dps: {e}")))?;
    let epoch = speed_mode(bus, joint, here, spd_ref).await?;
    let started = Instant::now();
    let deadline = started + plan.timeout;
    let mut watch = bus.watch();
    let mut last_sample: Option<Instant> = None;
    let mut stall = StallWatch::new(started, plan.speed_dps, plan.current_limit_a);
    loop {
        aborted_by_event(bus, events)?;
        revoked(bus, id, epoch)?;
        let snap = watch.borrow_and_update().clone();
        let dev = snap.devices.get(&id);
        unfit(dev)?;
        if let Some(deg) = dev.and_then(measured_angle_raw).map(units::angle_deg) {
            if bound.reached(plan.direction, deg, plan.speed_dps) {
                return Err(Ended::Failed(bound.failure(deg)));
            }
        }
        if let Some(stop_deg) = stalled_at(dev, started, &mut last_sample, &mut stall) {
            return Ok(stop_deg);
        }
        let now = Instant::now();
        if now >= deadline {
            return Err(Ended::Failed(format!(
                "no stop found within {} ms (moved: {})",
                plan.timeout.as_millis(),
                stall.moved()
            )));
        }
        let wait = (deadline - now).min(Duration::from_millis(20));
        let _ = tokio::time::timeout(wait, watch.changed()).await;
    }
}

/// Speed 0 on the wire, speed mode, then the search's speed from `here`,
/// under the epoch the joint's own mode change led to; that epoch.
async fn speed_mode(
    bus: &BusHandle,
    joint: Admitted,
    here: i16,
    spd_ref: i16,
) -> Result<Epoch, Ended> {
    let id = joint.id;
    // The speed the joint last had stays with it into speed mode (in
    // position mode it is the speed limit): make it 0 first.
    if !speed_zero_on_wire(bus, id).await {
        return Err(Ended::Failed(
            "speed 0 was not seen on the wire before speed mode: not starting".into(),
        ));
    }
    revoked(bus, id, joint.epoch)?;
    bus.set_mode(id, CtrlMode::Speed)
        .await
        .map_err(|e| Ended::Failed(format!("could not switch to speed mode: {e}")))?;
    // The search drives the joint under the epoch its own mode change led
    // to from the one it was admitted with: anything else that advanced it
    // (an e-stop, a disable, an enable, another mode change, a reset, since
    // the job was admitted) ends the search, and its speed cannot reach the
    // joint after that.
    let epoch = joint.epoch.after_own_mode_change();
    revoked(bus, id, epoch)?;
    bus.set_targets_under(
        &[(
            id,
            Setpoint {
                pos_ref: here,
                spd_ref,
            },
            epoch,
        )],
        Source::Homing,
    );
    Ok(epoch)
}

/// The joint's newest telemetry sample since the search began, read for a
/// stall; the angle it stalled at once the watch says so.
fn stalled_at(
    dev: Option<&DeviceState>,
    started: Instant,
    last_sample: &mut Option<Instant>,
    stall: &mut StallWatch,
) -> Option<f64> {
    let dev = dev?;
    let (info, at) = dev.info02.as_ref().map(|(i, at)| (*i, *at))?;
    if last_sample.is_some_and(|last| at <= last) || at < started {
        return None;
    }
    *last_sample = Some(at);
    let fw = firmware_of(dev);
    let sample = Sample {
        at,
        speed_dps: units::output_deg_per_s(info.speed_rpm(fw)),
        current_a: units::current_a(info.q_cur),
    };
    stall.stalled(sample).then(|| units::angle_deg(info.angle))
}

/// An e-stop on the joint's bus ends the search (checked between samples,
/// and the joint's own state tells it too).
pub(super) fn aborted_by_event(
    bus: &BusHandle,
    events: &mut broadcast::Receiver<BusEvent>,
) -> Result<(), Ended> {
    loop {
        match events.try_recv() {
            Ok(BusEvent::Estop { bus: b }) if b == bus.name() => {
                return Err(Ended::Aborted("e-stop".into()))
            }
            Ok(_) | Err(broadcast::error::TryRecvError::Lagged(_)) => continue,
            Err(_) => return Ok(()),
        }
    }
}

/// The joint's motion epoch moved on from the search's own.
fn revoked(bus: &BusHandle, id: u8, epoch: Epoch) -> Result<(), Ended> {
    if bus.authority().admits(id, epoch) {
        return Ok(());
    }
    let reason = match bus.authority().last_revoked(id) {
        Some(Revoked::Estopped) => "e-stop".to_string(),
        Some(why) => format!("the joint's commands were revoked ({})", why.name()),
        None => "the joint is no longer enabled".to_string(),
    };
    Err(Ended::Aborted(reason))
}

/// Offline, faulted or no longer enabled: the search cannot go on.
fn unfit(dev: Option<&DeviceState>) -> Result<(), Ended> {
    let aborted = |reason: String| Err(Ended::Aborted(reason));
    let Some(dev) = dev.filter(|d| d.online) else {
        return aborted("the joint went offline".into());
    };
    if let Some((info, _)) = &dev.info01 {
        if info.fsm == fsm::FAULT || active_fault(info.err_code) != 0 {
            let name = fault_name(active_fault(info.err_code));
            return aborted(format!("the joint faulted ({name})"));
        }
        if !is_enabled(info) {
            let why = dev.disabled_reason.map_or("disabled", |r| r.name());
            let reason = if why == "estop" {
                "e-stop".to_string()
            } else {
                format!("the joint was disabled ({why})")
            };
            return aborted(reason);
        }
    }
    Ok(())
}
