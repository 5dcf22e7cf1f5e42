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
//! finger, see [`super::grasp_finger`]; how samples are read, see
//! [`super::grasp_detect`]. `docs/grasping.md` maps the current to torque
//! and fingertip force.
//!
//! Where a finger closes to: the request's `close_to_deg`, else the hand's
//! pose `closed` (its angle for that joint), else the top of the joint's
//! allowed range in its calibrated frame (fingers close towards higher
//! joint angles; a flipped calibration makes it so).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use utoipa::ToSchema;

use super::error::{ControlError, ControlResult};
use super::grasp_book::{
    Busy, Command, FingerGrasp, FingerState, GraspSettings, GraspView, Job, Slot,
};
use super::grasp_finger::{self, Finger, Plan, Prepared};
use super::joints::known_device;
use super::targets::admit_positions;
use super::Control;
use crate::control::device::measured_angle_raw;
use crate::hands::{Calibration, Hand, HandJoint};
use crate::protocol::units;

/// The pose a finger closes to by default.
pub(crate) const CLOSED_POSE: &str = "closed";
/// The largest closing (and opening) speed, output °/s.
const MAX_SPEED_DPS: f64 = 180.0;
/// The contact threshold by default: this share of the hold current ...
const THRESHOLD_SHARE: f64 = 0.3;
/// ... but at least this (above the current's noise), A.
const MIN_THRESHOLD_A: f64 = 0.02;
/// How long `release` and `stop` wait for the fingers to end.
const END_WAIT: Duration = Duration::from_secs(20);

/// One finger of the hand, by its joint name, and where it closes to.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GraspJoint {
    /// The joint's name in the hand.
    #[schema(example = "index")]
    pub joint: String,
    /// Where it closes to at most, degrees (calibrated frame); default:
    /// the hand's pose `closed`, else the top of the joint's allowed range.
    #[schema(example = 90.0)]
    pub close_to_deg: Option<f64>,
}

/// How to grasp.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"speed_dps": 30.0, "hold_current_a": 0.2}))]
pub(crate) struct GraspRequest {
    /// Closing speed at the output, °/s (0 < s ≤ 180).
    #[schema(example = 30.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub speed_dps: f64,
    /// The force each finger holds with, as a q current, A (0 < I ≤ 5.625,
    /// below the joint's own current limit and its protection level).
    #[schema(example = 0.2, exclusive_minimum = 0.0, maximum = 5.625)]
    pub hold_current_a: f64,
    /// The rise of q current over what the finger draws moving freely that
    /// counts as contact, A (0 < t < hold_current_a; default 30 % of
    /// hold_current_a, at least 0.02).
    #[schema(example = 0.06, exclusive_minimum = 0.0)]
    pub contact_threshold_a: Option<f64>,
    /// The fingers (1..=64, each once); default: every joint of the hand.
    pub joints: Option<Vec<GraspJoint>>,
}

/// How to let go.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"open_deg": 20.0}))]
pub(crate) struct ReleaseRequest {
    /// Open to this pose of the hand (its angle for each finger).
    #[schema(example = "open")]
    pub pose: Option<String>,
    /// Open each finger by this much from where it is, degrees (0 < d ≤ 180).
    #[schema(example = 20.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub open_deg: Option<f64>,
    /// Opening speed, °/s (default: the closing speed).
    #[schema(example = 30.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub speed_dps: Option<f64>,
}

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
    tokio::spawn(run(job, fingers, plan));
    get(state, id)
}

/// The job: every limit reduced and verified (or none of the fingers
/// moves and every limit goes back), then each finger in its own task.
async fn run(job: Arc<Job>, fingers: Vec<Finger>, plan: Plan) {
    let prepared: Vec<Result<Prepared, (Prepared, String)>> =
        futures_util::future::join_all(fingers.iter().map(|f| grasp_finger::prepare(f, &plan)))
            .await;
    if let Some(why) = prepared
        .iter()
        .find_map(|p| p.as_ref().err().map(|e| e.1.clone()))
    {
        let restores = fingers.iter().zip(&prepared).map(|(f, p)| {
            let p = match p {
                Ok(p) | Err((p, _)) => *p,
            };
            async move { (f, grasp_finger::restore(&f.bus, f.id, p).await) }
        });
        for (f, restored) in futures_util::future::join_all(restores).await {
            grasp_finger::set(&f.slot, |s| {
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
        .map(|(f, p)| tokio::spawn(grasp_finger::run(f, plan, p, job.command.subscribe())))
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
    let goals = open_goals(state, &job, req)?;
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

async fn wait_done(state: &Control, id: u64, job: &Job) -> ControlResult<GraspView> {
    let mut done = job.done.subscribe();
    let _ = tokio::time::timeout(END_WAIT, done.wait_for(|d| *d)).await;
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

/// Each finger's opening goal (device degrees), in job order; `None` for
/// a finger no longer in the grasp.
fn open_goals(state: &Control, job: &Job, req: &ReleaseRequest) -> ControlResult<Vec<Option<f64>>> {
    if req.pose.is_some() && req.open_deg.is_some() {
        return Err(ControlError::invalid(
            "pose",
            "give `pose` or `open_deg`, not both",
        ));
    }
    let pose = match &req.pose {
        Some(name) => Some(
            state
                .hands()
                .and_then(|s| s.pose(&job.hand, name))
                .ok_or_else(|| {
                    ControlError::not_found(
                        "unknown-pose",
                        format!("hand `{}` has no pose named `{name}`", job.hand),
                    )
                })?,
        ),
        None => None,
    };
    if let Some(d) = req.open_deg {
        if !(d.is_finite() && d > 0.0 && d <= 180.0) {
            return Err(ControlError::out_of_range(
                "open_deg",
                d,
                (0.0, 180.0),
                "deg",
            ));
        }
    }
    job.slots
        .iter()
        .map(|slot| {
            let f = super::homing_book::lock(slot).clone();
            if !f.state.live() {
                return Ok(None);
            }
            open_goal(state, &f, pose.as_ref(), req.open_deg).map(Some)
        })
        .collect()
}

/// Where one finger opens to (device degrees), checked against its limits.
fn open_goal(
    state: &Control,
    f: &FingerGrasp,
    pose: Option<&crate::hands::Pose>,
    open_deg: Option<f64>,
) -> ControlResult<f64> {
    let cal = state.calibration(&f.bus, f.id);
    let soft = state.limits(&f.bus, f.id);
    let here = here_joint_deg(state, &f.bus, f.id, &cal)?;
    let field = format!("fingers.{}", f.joint);
    let goal = match (pose, open_deg) {
        (Some(p), _) => *p.get(&f.joint).ok_or_else(|| {
            ControlError::invalid(
                "pose",
                format!("the pose has no angle for joint `{}`", f.joint),
            )
        })?,
        (None, Some(d)) => here - (f.close_to_deg - here).signum() * d,
        (None, None) => f.start_deg,
    };
    soft.check_joint_position(&cal, &field, goal, &format!("joint `{}`", f.joint))
}

fn here_joint_deg(state: &Control, bus: &str, id: u8, cal: &Calibration) -> ControlResult<f64> {
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

fn settings(req: &GraspRequest) -> ControlResult<GraspSettings> {
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
    if !(threshold.is_finite() && threshold > 0.0 && threshold < hold) {
        return Err(
            ControlError::out_of_range("contact_threshold_a", threshold, (0.0, hold), "A")
                .with_detail(format!(
            "contact_threshold_a = {threshold} A must lie above 0 and below hold_current_a \
             ({hold} A): the current a finger holds with never rises over a higher one"
        )),
        );
    }
    Ok(GraspSettings {
        speed_dps,
        hold_current_a: hold,
        contact_threshold_a: threshold,
    })
}

fn speed(field: &str, s: f64) -> ControlResult<f64> {
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

fn hand_named(state: &Control, hand: &str) -> ControlResult<Hand> {
    state
        .hands()
        .and_then(|s| s.hand(hand))
        .cloned()
        .ok_or_else(|| ControlError::not_found("unknown-hand", format!("no hand named `{hand}`")))
}

/// The fingers asked (or every joint of the hand), each once, with the
/// closing limit asked for it.
fn fingers(hand: &Hand, req: &GraspRequest) -> ControlResult<Vec<(HandJoint, Option<f64>)>> {
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
fn admit(
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
    let field = format!("joints.{}.close_to_deg", joint.name);
    let close_to_joint_deg = match close_to {
        Some(d) => d,
        None => default_close_to(state, hand, joint, &cal, &soft),
    };
    let who = format!("joint `{}`", joint.name);
    let close_to_deg = soft.check_joint_position(&cal, &field, close_to_joint_deg, &who)?;
    let start_deg = here_joint_deg(state, &joint.bus, joint.id, &cal)?;
    soft.check_speed("speed_dps", settings.speed_dps, &who)?;
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
fn default_close_to(
    state: &Control,
    hand: &str,
    joint: &HandJoint,
    cal: &Calibration,
    soft: &super::limits::JointLimits,
) -> f64 {
    let closed = state
        .hands()
        .and_then(|s| s.pose(hand, CLOSED_POSE))
        .and_then(|p| p.get(&joint.name).copied());
    closed.unwrap_or_else(|| {
        let (_, hi) = cal.range_to_joint((soft.min_deg, soft.max_deg));
        cal.range_deg.map_or(hi, |(_, top)| hi.min(top))
    })
}

fn unknown(id: u64) -> ControlError {
    ControlError::not_found("unknown-grasp", format!("no grasp with id {id}"))
}

/// 409 naming the grasp that has the joint.
fn busy(b: &Busy) -> ControlError {
    ControlError::conflict(
        "grasp-running",
        "Joint already grasping",
        format!(
            "joint {} of bus `{}` is in grasp {} (GET /api/v1/grasps/{}): one grasp per joint \
             at a time; release or stop it first",
            b.id, b.bus, b.job, b.job
        ),
    )
}
