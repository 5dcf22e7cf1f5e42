//! Which joints a homing job drives, and whether each may start: named
//! once each, in no other job, running (not aligning), in position mode,
//! admitted under its motion epoch.

use crate::bus::authority::Epoch;
use crate::bus::handle::DeviceState;
use crate::bus::BusHandle;
use crate::control::device::firmware_of;
use crate::control::error::{ControlError, ControlResult};
use crate::control::joints::{known_device, JointRef};
use crate::control::limits::JointLimits;
use crate::control::lookup::resolve_joint;
use crate::control::state::Control;
use crate::control::targets::admit;
use crate::protocol::status::{fsm, fsm_name};
use crate::protocol::{CtrlMode, InfoBlock, ReplyBody};

use super::request::{check_stop_at, HomingRequest, Plan};
use crate::control::books::homing::Busy;

/// The joints named, or every joint of the hand; each once.
pub(super) fn joints(state: &Control, req: &HomingRequest) -> ControlResult<Vec<JointRef>> {
    let list: Vec<JointRef> = match (&req.joints, &req.hand) {
        (Some(joints), None) if !joints.is_empty() && joints.len() <= 64 => joints
            .iter()
            .enumerate()
            .map(|(i, j)| {
                resolve_joint(
                    state,
                    &format!("joints[{i}]"),
                    j.bus.as_deref(),
                    j.id,
                    j.hand.as_deref(),
                    j.joint.as_deref(),
                )
            })
            .collect::<ControlResult<_>>()?,
        (None, Some(hand)) => state
            .hand(hand)?
            .joints
            .iter()
            .map(|j| JointRef {
                bus: j.bus.clone(),
                id: j.id,
            })
            .collect(),
        _ => {
            return Err(ControlError::invalid(
                "joints",
                "give `joints` (1..=64 joints) or `hand`, not both",
            ))
        }
    };
    for (i, r) in list.iter().enumerate() {
        if list[..i].contains(r) {
            return Err(ControlError::duplicate(
                &format!("joints[{i}]"),
                format!("joint {} of bus `{}` appears twice", r.id, r.bus),
            ));
        }
    }
    Ok(list)
}

/// One joint of the job admitted: in no other homing or grasp, known,
/// its stop and speed within its limits, running, in position mode; its
/// soft limits and the epoch the job drives it under.
pub(super) async fn admit_joint(
    state: &Control,
    plan: &Plan,
    r: &JointRef,
) -> ControlResult<(JointLimits, Epoch)> {
    if let Some(job) = state.homings().running_job(&r.bus, r.id) {
        return Err(busy(&Busy {
            job,
            bus: r.bus.clone(),
            id: r.id,
        }));
    }
    if let Some(job) = state.grasps().running_job(&r.bus, r.id) {
        return Err(ControlError::conflict(
            "grasp-running",
            "Joint grasping",
            format!(
                "joint {} of bus `{}` is in grasp {job}: home it once the grasp ended",
                r.id, r.bus
            ),
        ));
    }
    let bus = state.bus(&r.bus)?;
    let snap = bus.snapshot();
    let dev = known_device(&snap, r.id)?;
    let soft = state.limits(&r.bus, r.id);
    check_stop_at(plan, &soft, r)?;
    soft.check_motion_speed(
        &"speed_dps",
        plan.speed_dps,
        firmware_of(dev),
        &format!("joint {} of bus `{}`", r.id, r.bus),
    )?;
    ensure_running(bus, dev).await?;
    // The job drives the joint under the epoch it is admitted with:
    // anything that advances it from here on ends the job.
    let epoch = admit(bus, dev, "homing")?;
    if dev.mode.is_some_and(|m| m != CtrlMode::Position) {
        return Err(ControlError::conflict(
            "wrong-mode",
            "Joint not in position mode",
            format!(
                "joint {} of bus `{}` is not in position mode: homing starts from position mode",
                r.id, r.bus
            ),
        ));
    }
    Ok((soft, epoch))
}

/// 409 naming the job that homes the joint.
pub(super) fn busy(b: &Busy) -> ControlError {
    ControlError::conflict(
        "homing-running",
        "Joint already being homed",
        format!(
            "joint {} of bus `{}` is being homed by homing job {} (GET /api/v1/homing/{}): \
             one homing per joint at a time; start again once it is done",
            b.id, b.bus, b.job, b.job
        ),
    )
}

/// A joint aligning its encoder after its first enable stands still
/// (fsm `align`), which the search would take for its stop: homing starts
/// only on a joint that runs. The latest poll tells when it says `run` or
/// `align` (an enable confirms the state it reached, so the snapshot has
/// seen it); otherwise the device is asked.
async fn ensure_running(bus: &BusHandle, dev: &DeviceState) -> ControlResult<()> {
    let cached = dev.info01.as_ref().map(|(i, _)| i.fsm);
    let state = match cached {
        Some(s @ (fsm::RUN | fsm::ALIGN)) => s,
        _ => match bus.read_info(dev.dev_id, InfoBlock::Info01).await?.body() {
            ReplyBody::Info01(info) => info.fsm,
            _ => {
                return Err(crate::bus::BusError::UnexpectedReply(format!(
                    "device {} answered INFO_01 with another block",
                    dev.dev_id
                ))
                .into())
            }
        },
    };
    match state {
        fsm::RUN => Ok(()),
        fsm::ALIGN => Err(ControlError::conflict(
            "not-aligned",
            "Joint still aligning",
            format!(
                "joint {} of bus `{}` is still aligning its encoder (fsm `align`) and stands \
                 still while it does, which homing would take for its stop: home it once it \
                 runs (fsm `run`)",
                dev.dev_id,
                bus.name()
            ),
        )),
        other => Err(ControlError::conflict(
            "not-enabled",
            "Device not enabled",
            format!(
                "homing needs joint {} of bus `{}` enabled and running; it is `{}` (enable it first)",
                dev.dev_id,
                bus.name(),
                fsm_name(other)
            ),
        )),
    }
}
