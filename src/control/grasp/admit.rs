//! Admitting a grasp: the request's settings checked (speed, hold current,
//! contact threshold), the hand's fingers named, and each finger admitted
//! (known, enabled by jointd, running, in position mode, in no other grasp
//! or homing, its closing limit and speed within its limits) with the
//! slot its task writes.

use std::sync::{Arc, Mutex};

use super::plan::Finger;
use super::request::{busy, GraspRequest, CLOSED_POSE};
use crate::control::books::grasps::{Busy, FingerGrasp, FingerState, GraspSettings};
use crate::control::device::{firmware_of, measured_angle_raw};
use crate::control::error::{ControlError, ControlResult, InvalidKind};
use crate::control::joints::known_device;
use crate::control::state::Control;
use crate::control::targets::admit_positions;
use crate::hands::{Calibration, Hand, HandJoint};
use crate::protocol::units;

/// The largest closing (and opening) speed, output °/s.
const MAX_SPEED_DPS: f64 = 180.0;
/// The contact threshold by default: this share of the hold current ...
const THRESHOLD_SHARE: f64 = 0.3;
/// ... but at least this (above the current's noise), A; a threshold
/// asked for below it would take the noise for contact.
const MIN_THRESHOLD_A: f64 = 0.02;
/// A finger may stand this far past its closing limit (degrees) and still
/// be closed to it: the reading's noise, not an opening.
const PAST_LIMIT_DEG: f64 = 0.5;

pub(super) fn here_joint_deg(
    state: &Control,
    bus: &str,
    id: u8,
    cal: &Calibration,
) -> ControlResult<f64> {
    let snap = state.bus(bus)?.snapshot();
    let dev = known_device(&snap, id)?;
    measured_angle_raw(dev)
        .map(|raw| cal.to_joint(units::angle_deg(raw)))
        .ok_or_else(|| {
            ControlError::conflict(
                "no-telemetry",
                "Joint angle unknown",
                format!("joint {id} of bus `{bus}` has not reported its angle yet"),
            )
        })
}

pub(super) fn settings(req: &GraspRequest) -> ControlResult<GraspSettings> {
    let speed_dps = speed("speed_dps", req.speed_dps)?;
    let hold = req.hold_current_a;
    let max_a = units::CURRENT_FULL_SCALE_A;
    if !(hold.is_finite() && hold > 0.0 && hold <= max_a) {
        return Err(ControlError::out_of_range(
            "hold_current_a",
            hold,
            (0.0, max_a),
            "A",
        ));
    }
    let threshold = req
        .contact_threshold_a
        .unwrap_or((THRESHOLD_SHARE * hold).max(MIN_THRESHOLD_A));
    if !(threshold.is_finite() && threshold >= MIN_THRESHOLD_A && threshold < hold) {
        return Err(ControlError::out_of_range(
            "contact_threshold_a",
            threshold,
            (MIN_THRESHOLD_A, hold),
            "A",
        )
        .with_detail(format!(
            "contact_threshold_a = {threshold} A must lie from {MIN_THRESHOLD_A} A (below it the \
             current's noise reads as contact) up to below hold_current_a ({hold} A): the current \
             a finger holds with never rises over a higher one"
        )));
    }
    Ok(GraspSettings {
        speed_dps,
        hold_current_a: hold,
        contact_threshold_a: threshold,
    })
}

pub(super) fn speed(field: &str, s: f64) -> ControlResult<f64> {
    if s.is_finite() && s > 0.0 && s <= MAX_SPEED_DPS {
        Ok(s)
    } else {
        Err(ControlError::out_of_range(
            field,
            s,
            (0.0, MAX_SPEED_DPS),
            "deg/s",
        ))
    }
}

pub(super) fn hand_named(state: &Control, hand: &str) -> ControlResult<Hand> {
    state.hand(hand).cloned()
}

/// The fingers asked (or every joint of the hand), each once, with the
/// closing limit asked for it.
pub(super) fn fingers(
    hand: &Hand,
    req: &GraspRequest,
) -> ControlResult<Vec<(HandJoint, Option<f64>)>> {
    let Some(list) = &req.joints else {
        return Ok(hand.joints.iter().map(|j| (j.clone(), None)).collect());
    };
    if list.is_empty() || list.len() > 64 {
        return Err(ControlError::invalid(
            "joints",
            "give 1..=64 joints, or none for the whole hand",
        ));
    }
    let mut out: Vec<(HandJoint, Option<f64>)> = Vec::with_capacity(list.len());
    for (i, j) in list.iter().enumerate() {
        let field = format!("joints[{i}].joint");
        let joint = hand.joint(&j.joint).ok_or_else(|| {
            let names: Vec<&str> = hand.joints.iter().map(|j| j.name.as_str()).collect();
            ControlError::invalid(
                &field,
                format!(
                    "hand `{}` has no joint `{}` (it has: {})",
                    hand.name,
                    j.joint,
                    names.join(", ")
                ),
            )
        })?;
        if out.iter().any(|(o, _)| o.name == joint.name) {
            return Err(ControlError::duplicate(
                &field,
                format!("joint `{}` appears twice", j.joint),
            ));
        }
        out.push((joint.clone(), j.close_to_deg));
    }
    Ok(out)
}

/// One finger: known, enabled by jointd, in position mode, in no other
/// grasp or homing, its closing limit within its limits; its slot.
pub(super) fn admit(
    state: &Control,
    hand: &str,
    index: usize,
    joint: &HandJoint,
    close_to: Option<f64>,
    settings: &GraspSettings,
) -> ControlResult<Finger> {
    let bus = state.bus(&joint.bus)?;
    if let Some(job) = state.grasps().running_job(&joint.bus, joint.id) {
        return Err(busy(&Busy {
            job,
            bus: joint.bus.clone(),
            id: joint.id,
        }));
    }
    if let Some(job) = state.homings().running_job(&joint.bus, joint.id) {
        return Err(ControlError::conflict(
            "homing-running",
            "Joint being homed",
            format!(
                "joint `{}` is being homed by homing job {job}: grasp once it is done",
                joint.name
            ),
        ));
    }
    let snap = bus.snapshot();
    let dev = known_device(&snap, joint.id)?;
    let epoch = admit_positions(bus, dev, "a grasp")?;
    running(dev, joint)?;
    let cal = state.calibration(&joint.bus, joint.id);
    let soft = state.limits(&joint.bus, joint.id);
    let who = format!("joint `{}`", joint.name);
    soft.check_motion_speed(&"speed_dps", settings.speed_dps, firmware_of(dev), &who)?;
    let field = format!("joints.{}.close_to_deg", joint.name);
    let close_to_joint_deg = match close_to {
        Some(d) => d,
        None => default_close_to(state, hand, joint, &cal, &soft, &field)?,
    };
    let close_to_deg = soft.check_joint_position(&cal, &field, close_to_joint_deg, &who)?;
    let start_deg = here_joint_deg(state, &joint.bus, joint.id, &cal)?;
    would_open(&field, &joint.name, close_to_joint_deg, start_deg)?;
    let slot = Arc::new(Mutex::new(FingerGrasp {
        bus: joint.bus.clone(),
        id: joint.id,
        joint: joint.name.clone(),
        state: FingerState::Starting,
        contact: false,
        contact_deg: None,
        contact_after_ms: None,
        q_current_a: None,
        close_to_deg: close_to_joint_deg,
        start_deg,
        previous_current_limit_a: None,
        current_limit_restored: false,
        reason: None,
    }));
    Ok(Finger {
        bus: bus.clone(),
        id: joint.id,
        index,
        epoch,
        cal,
        close_to_deg,
        slot,
    })
}

/// Fingers close towards higher angles of their calibrated frame (a
/// calibration flips a joint whose device turns the other way): a closing
/// limit below where a finger stands would open it, and is refused.
pub(super) fn would_open(field: &str, joint: &str, close_to: f64, here: f64) -> ControlResult<()> {
    if close_to + PAST_LIMIT_DEG >= here {
        return Ok(());
    }
    Err(ControlError::invalid_as(
        InvalidKind::WouldOpen,
        field,
        format!(
            "joint `{joint}`: closing to {close_to:.1}° is below where it stands ({here:.1}°); \
             fingers close towards higher angles, so it would open: give a limit above where \
             the finger stands, or none for its default"
        ),
    ))
}

/// A joint still aligning (or, under rev 2.0.8, starting) is enabled but
/// does not follow targets yet, and its finger would read as stalled: a
/// grasp starts only on joints whose latest state says `run`.
fn running(dev: &crate::bus::handle::DeviceState, joint: &HandJoint) -> ControlResult<()> {
    let state = dev.info01.as_ref().map(|(i, _)| i.fsm);
    if state == Some(crate::protocol::status::fsm::RUN) {
        return Ok(());
    }
    let name = state.map_or("unknown", crate::protocol::status::fsm_name);
    Err(ControlError::conflict(
        "not-aligned",
        "Joint not running yet",
        format!(
            "joint `{}` is `{name}`, not `run`: a grasp starts once every finger runs",
            joint.name
        ),
    ))
}

/// The pose `closed`'s angle for the joint, else the top of its allowed
/// range (calibrated frame: soft limits, device range, calibration range).
/// A joint with no range configured (neither soft limits nor a
/// calibration range) has no top but the protocol's ±255°: a finger in free
/// air would turn on towards it, so the grasp is refused, saying how to
/// give it one.
fn default_close_to(
    state: &Control,
    hand: &str,
    joint: &HandJoint,
    cal: &Calibration,
    soft: &crate::control::limits::JointLimits,
    field: &str,
) -> ControlResult<f64> {
    let closed = state
        .hands()
        .and_then(|s| s.pose(hand, CLOSED_POSE))
        .and_then(|p| p.get(&joint.name).copied());
    if let Some(deg) = closed {
        return Ok(deg);
    }
    let unbounded = soft.min_deg <= -units::MAX_ANGLE_DEG && soft.max_deg >= units::MAX_ANGLE_DEG;
    if unbounded && cal.range_deg.is_none() {
        return Err(ControlError::invalid(
            field,
            format!(
                "joint `{}` has no range to close to (only the protocol's ±{}°): give \
                 `close_to_deg`, save the hand's `{CLOSED_POSE}` pose, or give the joint a \
                 range (soft limits in `[[limit]]`, or a calibration range)",
                joint.name,
                units::MAX_ANGLE_DEG
            ),
        ));
    }
    let (_, hi) = cal.range_to_joint((soft.min_deg, soft.max_deg));
    Ok(cal.range_deg.map_or(hi, |(_, top)| hi.min(top)))
}
