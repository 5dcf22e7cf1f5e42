//! Homing: an opt-in routine per joint (or every joint of a hand) that
//! finds the joint's hard stop and records it as the joint's calibration
//! offset. It starts only on joints that run (fsm `run`: a joint still
//! aligning stands still, which would look like its stop) and are in no
//! other running homing job. Per joint, in its own task:
//!
//! 1. read the current limit (INFO_04) and write a reduced one (RAM only,
//!    verified by read-back): a joint pushing into its stop must not hurt
//!    the finger or the gearbox;
//! 2. speed 0 on the wire, then speed mode, then a slow speed towards the
//!    stop; watch the telemetry until the joint stalls (its speed drops
//!    under a fifth of the asked speed for [`STALL_CONFIRM`], after it
//!    moved) or pushes (the same, with the q current near the reduced
//!    limit). The search is bounded: by the joint's soft limits and by
//!    `max_travel_deg` from where it started; reaching either ends the job
//!    `failed` ("no hard stop within ..."), nothing saved;
//! 3. the stall's angle becomes the calibration offset (the stop reads
//!    `stop_at_deg` from then on); speed 0, position mode, back off by
//!    `backoff_deg`;
//! 4. the previous current limit is written back **whatever happened**
//!    (found, timed out, out of travel, e-stopped, faulted, offline), and
//!    read back: the answer says `current_limit_restored` only when the
//!    read-back shows the previous limit.
//!
//! Speed 0 is written (and seen on the wire) before the joint leaves speed
//! mode, whichever way the search ended; a task that ends without getting
//! there (a panic) writes it as it unwinds. An e-stop, a fault, the joint
//! disabled or offline abort at once: after an e-stop nothing but speed 0,
//! the mode and the current limit is written. A job is polled with
//! `GET /api/v1/homing/{id}`.
//!
//! # Layout
//! One-way: each file imports only from files above it.
//! - `book`: the homing jobs, one per joint, as `GET` shows them.
//! - `request`: what a job is asked for, checked into its plan.
//! - `admit`: the job's joints, each admitted (running, in position mode, in no other job).
//! - `stall`: when the samples say the joint stalls at its stop; the search's bounds.
//! - `hold`: speed 0 on the wire, then position mode; the guard for a task unwinding.
//! - `search`: speed mode towards the stop until it stalls, a bound, or an abort.
//! - `backoff`: off the stop once found.
//! - this file: starting a job, each joint's task, the offset saved, the limit restored.

mod admit;
mod backoff;
mod hold;
mod request;
mod search;
mod stall;

use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::bus::BusHandle;
use crate::control::books::homing::{HomingState, HomingView, JointHoming, Slot};
use crate::control::books::lock::lock;
use crate::control::error::{ControlError, ControlResult};
use crate::control::limits::JointLimits;
use crate::control::state::Control;
use crate::control::{calibration, current_limit};
use crate::protocol::units;
use crate::protocol::ConfigParam;
use admit::{admit_joint, busy, joints};
use backoff::back_off;
use hold::{hold_here, SpeedZero};
pub(crate) use request::HomingRequest;
use request::{plan, Plan};
use search::{search, Admitted, Ended};

/// Checks the request, then homes each joint in its own task; the job as
/// it starts.
pub(crate) async fn start(state: &Arc<Control>, req: &HomingRequest) -> ControlResult<HomingView> {
    let plan = plan(req)?;
    let joints = joints(state, req)?;
    let mut limits = Vec::with_capacity(joints.len());
    for r in &joints {
        limits.push(admit_joint(state, &plan, r).await?);
    }
    let slots: Vec<Slot> = joints
        .iter()
        .map(|r| {
            Arc::new(Mutex::new(JointHoming {
                bus: r.bus.clone(),
                id: r.id,
                state: HomingState::Running,
                phase: "starting",
                reason: None,
                hard_stop_device_deg: None,
                offset_deg: None,
                previous_current_limit_a: None,
                current_limit_restored: false,
            }))
        })
        .collect();
    // Checked again under the book's lock: another request may have
    // started a job on one of these joints while this one read the bus.
    let id = state.homings().add(slots.clone()).map_err(|b| busy(&b))?;
    // A grasp admitted meanwhile on one of these joints passed its check
    // of this book before the job was in it: whichever of the two sees
    // the other now stands down, so they never both drive a joint.
    if let Some((r, grasp)) = joints
        .iter()
        .find_map(|r| state.grasps().running_job(&r.bus, r.id).map(|g| (r, g)))
    {
        let why = format!(
            "joint {} of bus `{}` is in grasp {grasp}, started at the same time",
            r.id, r.bus
        );
        for slot in &slots {
            let mut j = lock(slot);
            j.state = HomingState::Failed;
            j.reason = Some(why.clone());
        }
        return Err(ControlError::conflict(
            "grasp-running",
            "Joint grasping",
            format!("{why}: home it once the grasp ended"),
        ));
    }
    for ((r, slot), (soft, epoch)) in joints.into_iter().zip(slots).zip(limits) {
        let bus = state.bus(&r.bus)?.clone();
        let state = state.clone();
        let joint = Admitted { id: r.id, epoch };
        tokio::spawn(async move { home(state, bus, joint, plan, soft, slot, id).await });
    }
    tracing::info!(homing_id = id, ?plan, "homing started");
    state
        .homings()
        .view(id)
        .ok_or_else(|| ControlError::not_found("unknown-homing", format!("no homing with id {id}")))
}

/// Homing job `id` as it stands.
pub(crate) fn get(state: &Control, id: u64) -> ControlResult<HomingView> {
    state
        .homings()
        .view(id)
        .ok_or_else(|| ControlError::not_found("unknown-homing", format!("no homing with id {id}")))
}

fn set(slot: &Slot, edit: impl FnOnce(&mut JointHoming)) {
    edit(&mut lock(slot));
}

/// The search's current limit, raw: below the joint's own (`previous`),
/// or why homing cannot reduce it.
fn reduced_limit(plan: &Plan, previous: u16) -> Result<u16, String> {
    match units::current_limit_to_raw(plan.current_limit_a) {
        Ok(raw) if raw < previous => Ok(raw),
        _ => Err(format!(
            "current_limit_a = {} A is not below the joint's own limit ({:.3} A): homing needs a reduced limit",
            plan.current_limit_a,
            units::current_limit_a(previous)
        )),
    }
}

/// Homes one joint; whatever happens, its previous current limit is
/// written back (and read back) before the job says it ended.
async fn home(
    state: Arc<Control>,
    bus: BusHandle,
    joint: Admitted,
    plan: Plan,
    soft: JointLimits,
    slot: Slot,
    job: u64,
) {
    let id = joint.id;
    let mut events = bus.events();
    let previous = match current_limit::read(&bus, id).await {
        Ok(raw) => raw,
        Err(why) => return finish(&slot, job, Err(Ended::Failed(why))),
    };
    set(&slot, |s| {
        s.previous_current_limit_a = Some(units::current_limit_a(previous));
    });
    let limit = match reduced_limit(&plan, previous) {
        Ok(raw) => raw,
        Err(why) => {
            // Nothing was written: the limit just read is the previous one.
            set(&slot, |s| s.current_limit_restored = true);
            return finish(&slot, job, Err(Ended::Failed(why)));
        }
    };
    bus.take_over(&[id]);
    let outcome = limited_search(&bus, joint, &plan, &soft, limit, &slot, &mut events).await;
    let outcome = match outcome {
        Ok(stop_deg) => {
            set(&slot, |s| {
                s.phase = "backing_off";
                s.hard_stop_device_deg = Some(stop_deg);
            });
            let offset = record(&state, &bus, id, &plan, stop_deg);
            back_off(&bus, id, &plan, &soft, stop_deg, &mut events).await;
            offset
        }
        Err(ended) => Err(ended),
    };
    set(&slot, |s| s.phase = "restoring");
    let owed_slot = slot.clone();
    let settled = move || set(&owed_slot, |s| s.current_limit_restored = true);
    let restored = restore(&bus, id, previous, settled).await;
    set(&slot, |s| s.current_limit_restored = restored);
    finish(&slot, job, outcome);
}

/// The search under the reduced current limit `limit`; then, however it
/// ended, the joint stops pushing and leaves speed mode (a task unwinding
/// writes speed 0 on its way out).
async fn limited_search(
    bus: &BusHandle,
    joint: Admitted,
    plan: &Plan,
    soft: &JointLimits,
    limit: u16,
    slot: &Slot,
    events: &mut tokio::sync::broadcast::Receiver<crate::bus::handle::BusEvent>,
) -> Result<f64, Ended> {
    let id = joint.id;
    let mut guard = SpeedZero {
        bus: bus.clone(),
        id,
        armed: false,
    };
    let outcome = match bus.write_config(id, ConfigParam::MaxCur(limit)).await {
        Ok(_) => {
            set(slot, |s| s.phase = "searching");
            guard.armed = true;
            search(bus, joint, plan, soft, events).await
        }
        Err(e) => Err(Ended::Failed(format!(
            "could not reduce the current limit: {e}"
        ))),
    };
    if guard.armed {
        // Stop pushing and leave speed mode, however the search ended.
        hold_here(bus, id).await;
        guard.armed = false;
    }
    outcome
}

fn finish(slot: &Slot, job: u64, outcome: Result<f64, Ended>) {
    let mut s = lock(slot);
    s.phase = "done";
    match outcome {
        Ok(offset) => {
            s.state = HomingState::Homed;
            s.offset_deg = Some(offset);
            tracing::info!(homing_id = job, bus = %s.bus, id = s.id, offset_deg = offset,
                stop_deg = ?s.hard_stop_device_deg, restored = s.current_limit_restored, "joint homed");
        }
        Err(Ended::Failed(why)) => {
            s.state = HomingState::Failed;
            tracing::warn!(homing_id = job, bus = %s.bus, id = s.id, restored = s.current_limit_restored, "homing failed: {why}");
            s.reason = Some(why);
        }
        Err(Ended::Aborted(reason)) => {
            s.state = HomingState::Aborted;
            tracing::warn!(homing_id = job, bus = %s.bus, id = s.id, restored = s.current_limit_restored, "homing aborted: {reason}");
            s.reason = Some(reason);
        }
    }
    if !s.current_limit_restored && s.previous_current_limit_a.is_some() {
        tracing::error!(homing_id = job, bus = %s.bus, id = s.id,
            previous_a = ?s.previous_current_limit_a,
            "the joint's current limit could not be written back: it keeps the reduced limit until set or power-cycled");
    }
}

/// Saves the offset that makes the stop read `stop_at_deg` (flip and range
/// kept); the offset.
fn record(
    state: &Control,
    bus: &BusHandle,
    id: u8,
    plan: &Plan,
    stop_deg: f64,
) -> Result<f64, Ended> {
    let mut cal = state.calibration(bus.name(), id);
    cal.offset_deg = stop_deg - cal.sign() * plan.stop_at_deg;
    cal.homed_at_ms = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .ok()
        .map(|d| d.as_millis() as u64);
    calibration::save(state, bus.name(), id, cal)
        .map(|()| cal.offset_deg)
        .map_err(|e| Ended::Failed(format!("the stop was found but not saved: {e}")))
}

/// Writes the previous current limit back and reads it back (owed when it
/// cannot be: `settled` says when it is back).
async fn restore(
    bus: &BusHandle,
    id: u8,
    previous: u16,
    settled: impl FnOnce() + Send + 'static,
) -> bool {
    current_limit::restore(bus, id, previous, "homing", settled).await
}
