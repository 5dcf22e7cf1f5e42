//! Grasping: a hand's fingers close at a set speed until each feels
//! contact, then hold with a set force, until released (opened back to
//! where they started, to a pose, or by an angle) or stopped. A grasp is a
//! motion like a move or a homing job: admitted under each joint's motion
//! epoch (an e-stop, a disable, a reset, a mode change end it), bounded by
//! the soft limits, one per joint.
//!
//! The force is a q current (`hold_current_a`): each finger's current
//! limit (MAX_CUR, RAM only) is set to it, written and verified on every
//! finger before any finger moves, and the fingers close in position mode
//! towards their closing limit under it: pressing on the object, the
//! position loop draws what the limit lets it and no more. The previous
//! limit is written back (and read back) however the grasp ends. Per
//! finger, see [`finger`] (its limit: [`limit`]);
//! how samples are read, see [`detect`]; what is checked
//! before anything starts, [`admit`]; where a release opens
//! to, [`open`]. `docs/grasping.md` maps the current to torque
//! and fingertip force.
//!
//! Where a finger closes to: the request's `close_to_deg`, else the hand's
//! pose `closed` (its angle for that joint), else the top of the joint's
//! allowed range in its calibrated frame (fingers close towards higher
//! joint angles; a flipped calibration makes it so).
//!
//! # Layout
//! One-way: each file imports only from files above it.
//! - `book`: the grasp jobs, one per joint, and what each finger reports.
//! - `request`: what a grasp or a release asks for; a joint already in a grasp refused.
//! - `plan`: one grasp's fingers, speed and goals, shared by their tasks.
//! - `detect`: what a finger's samples mean (contact, no contact, a lost object), without I/O.
//! - `watch`: what a finger's task watches (fresh samples, a joint taken over, an end).
//! - `limit`: each finger's current limit lowered, written back however it ends.
//! - `admit`: what is checked before anything starts.
//! - `finger`: one finger closing, holding, releasing.
//! - `open`: where a release opens to.
//! - this file: starting, releasing and stopping a grasp.

pub(crate) mod admit;
pub(crate) mod detect;
pub(crate) mod finger;
pub(crate) mod limit;
pub(crate) mod open;
pub(crate) mod plan;
pub(crate) mod request;
pub(crate) mod watch;

use std::sync::Arc;
use std::time::{Duration, Instant};

use super::error::{ControlError, ControlResult};
use crate::control::books::grasps::{Command, FingerState, GraspView, Job, Slot};
use crate::control::state::Control;
use admit::{admit, fingers, hand_named, settings, speed};
use limit::Prepared;
use open::open_goals;
use plan::{Finger, Plan};
use request::busy;
pub(crate) use request::{GraspJoint, GraspRequest, ReleaseRequest};

/// How long `release` and `stop` wait for the fingers to end.
const END_WAIT: Duration = Duration::from_secs(20);

/// Checks the request, admits every finger, and starts the job: every
/// finger's limit first, then the fingers close. The job as it starts.
pub(crate) async fn start(
    state: &Arc<Control>,
    hand: &str,
    req: &GraspRequest,
) -> ControlResult<GraspView> {
    let settings = settings(req)?;
    let hand_of = hand_named(state, hand)?;
    let fingers = fingers(&hand_of, req)?;
    let mut admitted = Vec::with_capacity(fingers.len());
    for (i, (joint, close_to)) in fingers.into_iter().enumerate() {
        admitted.push(admit(state, hand, i, &joint, close_to, &settings)?);
    }
    let slots: Vec<Slot> = admitted.iter().map(|f| f.slot.clone()).collect();
    let job = Job::new(hand.to_owned(), settings, slots);
    let id = state.grasps().add(job.clone()).map_err(|b| busy(&b))?;
    stand_down_for_homing(state, &admitted, &job)?;
    let plan = Plan {
        grasp_id: id,
        speed_dps: settings.speed_dps,
        hold_a: settings.hold_current_a,
        threshold_a: settings.contact_threshold_a,
        called: Instant::now(),
    };
    let fingers = admitted;
    tracing::info!(
        grasp_id = id,
        hand,
        ?settings,
        fingers = fingers.len(),
        "grasp started"
    );
    // The grasp takes its joints from any move now: a move admitted after
    // this one takes them back, and the fingers then send nothing.
    for f in &fingers {
        f.bus.take_over(&[f.id]);
    }
    tokio::spawn(run(job, fingers, plan));
    get(state, id)
}

/// A homing admitted meanwhile on one of these joints passed its check of
/// the grasp book before the job was in it: whichever of the two sees the
/// other stands down, so they never both drive a joint. Here the grasp
/// does, its fingers aborted, with 409 naming the homing job.
fn stand_down_for_homing(state: &Control, admitted: &[Finger], job: &Job) -> ControlResult<()> {
    if let Some((bus, joint, homing)) = admitted.iter().find_map(|f| {
        // Read out first: no lock of a finger is held while the homing
        // book takes its own.
        let (bus, joint) = {
            let s = crate::control::books::lock::lock(&f.slot);
            (s.bus.clone(), s.id)
        };
        let homing = state.homings().running_job(&bus, joint)?;
        Some((bus, joint, homing))
    }) {
        let why = format!("joint {joint} of bus `{bus}` is being homed by homing job {homing}");
        for slot in &job.slots {
            let mut f = crate::control::books::lock::lock(slot);
            f.state = FingerState::Aborted;
            f.reason = Some(format!("{why}, started at the same time"));
        }
        job.done.send_replace(true);
        return Err(ControlError::conflict(
            "homing-running",
            "Joint being homed",
            format!("{why}: grasp once it is done"),
        ));
    }
    Ok(())
}

/// The job: every limit reduced and verified (or none of the fingers
/// moves and every limit goes back), then each finger in its own task.
async fn run(job: Arc<Job>, fingers: Vec<Finger>, plan: Plan) {
    let prepared: Vec<Result<Prepared, (Prepared, String)>> =
        futures_util::future::join_all(fingers.iter().map(|f| limit::prepare(f, &plan))).await;
    if let Some(why) = prepared
        .iter()
        .find_map(|p| p.as_ref().err().map(|e| e.1.clone()))
    {
        let restores = fingers.iter().zip(&prepared).map(|(f, p)| {
            let p = match p {
                Ok(p) | Err((p, _)) => *p,
            };
            let settled = limit::settled_in(&f.slot);
            async move { (f, limit::restore(&f.bus, f.id, p, settled).await) }
        });
        for (f, restored) in futures_util::future::join_all(restores).await {
            plan::set(&f.slot, |s| {
                s.state = FingerState::Failed;
                s.current_limit_restored = restored;
                s.reason = Some(why.clone());
            });
        }
        tracing::warn!(
            grasp_id = plan.grasp_id,
            "grasp failed before closing: {why}"
        );
        job.done.send_replace(true);
        return;
    }
    let tasks: Vec<_> = fingers
        .into_iter()
        .zip(prepared.into_iter().flatten())
        .map(|(f, p)| tokio::spawn(finger::run(f, plan, p, job.command.subscribe())))
        .collect();
    for t in tasks {
        if let Err(e) = t.await {
            tracing::error!(
                grasp_id = plan.grasp_id,
                "a grasp finger's task ended abnormally: {e}"
            );
        }
    }
    job.done.send_replace(true);
    tracing::info!(grasp_id = plan.grasp_id, "grasp ended");
}

/// Grasp job `id` as it stands.
pub(crate) fn get(state: &Control, id: u64) -> ControlResult<GraspView> {
    state.grasps().view(id).ok_or_else(|| unknown(id))
}

/// Opens every finger still in the grasp and ends it; answers once each
/// finger ended (limits restored), or after a bound.
pub(crate) async fn release(
    state: &Control,
    id: u64,
    req: &ReleaseRequest,
) -> ControlResult<GraspView> {
    let job = state.grasps().job(id).ok_or_else(|| unknown(id))?;
    ended_refused(id, &job)?;
    let speed_dps = match req.speed_dps {
        Some(s) => speed("speed_dps", s)?,
        None => job.settings.speed_dps,
    };
    let goals = open_goals(state, &job, req, speed_dps)?;
    job.command
        .send_replace(Command::Release { goals, speed_dps });
    wait_done(state, id, &job).await
}

/// Holds every finger where it is, restores the limits and ends the job.
/// Stopping a grasp that already ended answers its final state.
pub(crate) async fn stop(state: &Control, id: u64) -> ControlResult<GraspView> {
    let job = state.grasps().job(id).ok_or_else(|| unknown(id))?;
    job.command.send_replace(Command::Stop);
    wait_done(state, id, &job).await
}

/// Waits (bounded) for the job to end, if a waiting place is free
/// ([`crate::control::books::grasps::MAX_WAITING`]); the job as it stands.
async fn wait_done(state: &Control, id: u64, job: &Job) -> ControlResult<GraspView> {
    if let Some(_place) = state.grasps().wait_slot() {
        let mut done = job.done.subscribe();
        let _ = tokio::time::timeout(END_WAIT, done.wait_for(|d| *d)).await;
    }
    get(state, id)
}

fn ended_refused(id: u64, job: &Job) -> ControlResult<()> {
    if !*job.done.borrow() {
        return Ok(());
    }
    Err(ControlError::conflict(
        "grasp-ended",
        "Grasp already ended",
        format!("grasp {id} has ended (GET /api/v1/grasps/{id} says how): nothing to release"),
    ))
}

fn unknown(id: u64) -> ControlError {
    ControlError::not_found("unknown-grasp", format!("no grasp with id {id}"))
}
