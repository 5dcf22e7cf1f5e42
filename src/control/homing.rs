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

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use tokio::sync::broadcast;
use utoipa::ToSchema;

use crate::bus::authority::{Epoch, Revoked};
use crate::bus::handle::{BusEvent, DeviceState};
use crate::bus::{BusHandle, Setpoint, Source};
use crate::control::device::{firmware_of, is_enabled, measured_angle_raw};
use crate::control::error::{ControlError, ControlResult};
use crate::control::homing_book::{lock, Busy, HomingState, HomingView, JointHoming, Slot};
use crate::control::joints::{known_device, resolve_joint};
use crate::control::limits::JointLimits;
use crate::control::targets::{admit, wait_on_wire};
use crate::control::{calibration, current_limit};
use crate::control::{Control, JointRef};
use crate::protocol::status::{active_fault, fault_name, fsm, fsm_name};
use crate::protocol::units;
use crate::protocol::{ConfigParam, CtrlMode, InfoBlock, ReplyBody};

/// The joint must look stalled this long (by its samples' times).
const STALL_CONFIRM: Duration = Duration::from_millis(80);
/// Before the joint has been seen moving, a standstill counts as a stall
/// only after this long (it may start right at its stop).
const START_GRACE: Duration = Duration::from_millis(500);
/// Below this share of the asked speed the joint is not moving ...
const STALLED_SPEED_SHARE: f64 = 0.2;
/// ... above this one it is.
const MOVING_SPEED_SHARE: f64 = 0.5;
/// The q current counts as risen at this share of the reduced limit.
const PUSHING_CURRENT_SHARE: f64 = 0.6;
/// How long the back-off may take before the job ends anyway.
const BACKOFF_WAIT: Duration = Duration::from_secs(5);
/// Close enough to the back-off goal, degrees.
const BACKOFF_TOLERANCE_DEG: f64 = 0.5;
/// Speed limit of the back-off, rotor rpm (≈ 10 °/s at the output).
const BACKOFF_RPM: f64 = 1000.0;
/// The search ends this long (at the asked speed) before a bound, so
/// that the joint, still coasting while speed 0 reaches it, stays inside.
const BOUND_LOOKAHEAD: Duration = Duration::from_millis(100);
/// How far inside the device's ±255° a stop may read (`stop_at_deg`):
/// room for the largest back-off.
const STOP_AT_END_MARGIN_DEG: f64 = 30.0;
/// The largest `max_travel_deg`: the whole angle range.
const MAX_TRAVEL_DEG: f64 = 2.0 * units::MAX_ANGLE_DEG;

/// Which way the joint turns to find its stop (device angles).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Direction {
    #[default]
    Negative,
    Positive,
}

impl Direction {
    fn sign(self) -> f64 {
        match self {
            Self::Negative => -1.0,
            Self::Positive => 1.0,
        }
    }
}

/// One joint to home: by `bus` and `id`, or by `hand` and `joint`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct HomingJoint {
    #[schema(example = "sim0")]
    pub bus: Option<String>,
    #[schema(example = 1)]
    pub id: Option<i64>,
    pub hand: Option<String>,
    pub joint: Option<String>,
}

/// What to home and how. Defaults are gentle: 10 °/s under 0.3 A.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"joints": [{"bus": "sim0", "id": 1}], "direction": "negative",
    "speed_dps": 10.0, "current_limit_a": 0.3, "backoff_deg": 2.0, "stop_at_deg": 0.0, "timeout_ms": 20000}))]
pub(crate) struct HomingRequest {
    /// The joints (or give `hand`).
    pub joints: Option<Vec<HomingJoint>>,
    /// Every joint of this hand.
    pub hand: Option<String>,
    /// Which way (in device angles) the stop lies; default `negative`.
    pub direction: Option<Direction>,
    /// Search speed at the output, °/s (0 < s ≤ 90; default 10).
    #[schema(example = 10.0, exclusive_minimum = 0.0, maximum = 90.0)]
    pub speed_dps: Option<f64>,
    /// Current limit while searching, A (0 < I, below the joint's own
    /// limit; default 0.3).
    #[schema(example = 0.3, exclusive_minimum = 0.0, maximum = 5.625)]
    pub current_limit_a: Option<f64>,
    /// How far to move back off the stop, degrees (0..=30; default 2).
    #[schema(example = 2.0, minimum = 0.0, maximum = 30.0)]
    pub backoff_deg: Option<f64>,
    /// The joint angle the stop reads from then on (default 0). It must
    /// lie within the joint's soft range and at least 30° inside the ±255°
    /// angle range: 422 with the allowed range otherwise.
    #[schema(example = 0.0, minimum = -225.0, maximum = 225.0)]
    pub stop_at_deg: Option<f64>,
    /// The search fails ("no hard stop within ...") after the joint turned
    /// this far from where it started, degrees (0 < d ≤ 510; default: the
    /// width of the joint's soft range). It also fails at the soft limit
    /// in the search direction, whichever comes first.
    #[schema(example = 60.0, exclusive_minimum = 0.0, maximum = 510.0)]
    pub max_travel_deg: Option<f64>,
    /// Give up the search after this long, ms (0 < t ≤ 120000; default 20000).
    #[schema(example = 20000.0, exclusive_minimum = 0.0, maximum = 120000.0)]
    pub timeout_ms: Option<f64>,
}

/// The request checked.
#[derive(Debug, Clone, Copy)]
struct Plan {
    direction: Direction,
    speed_dps: f64,
    current_limit_a: f64,
    backoff_deg: f64,
    stop_at_deg: f64,
    /// `None`: the width of each joint's soft range.
    max_travel_deg: Option<f64>,
    timeout: Duration,
}

/// Checks the request, then homes each joint in its own task; the job as
/// it starts.
pub(crate) async fn start(state: &Arc<Control>, req: &HomingRequest) -> ControlResult<HomingView> {
    let plan = plan(req)?;
    let joints = joints(state, req)?;
    let mut limits = Vec::with_capacity(joints.len());
    for r in &joints {
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
        check_stop_at(&plan, &soft, r)?;
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
        limits.push((soft, epoch));
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

/// 409 naming the job that homes the joint.
fn busy(b: &Busy) -> ControlError {
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

/// `stop_at_deg` within the joint's soft range and not at the end of the
/// angle range: a stop reading ±255° leaves no angle beyond it for the
/// back-off, and an offset that puts it there cannot be saved.
fn check_stop_at(plan: &Plan, soft: &JointLimits, r: &JointRef) -> ControlResult<()> {
    let lo = soft
        .min_deg
        .max(-units::MAX_ANGLE_DEG + STOP_AT_END_MARGIN_DEG);
    let hi = soft
        .max_deg
        .min(units::MAX_ANGLE_DEG - STOP_AT_END_MARGIN_DEG);
    let x = plan.stop_at_deg;
    if (lo..=hi).contains(&x) {
        return Ok(());
    }
    let err = ControlError::out_of_range("stop_at_deg", x, (lo, hi), "deg").with_detail(format!(
        "stop_at_deg = {x} deg is outside what joint {} of bus `{}` allows, {lo}..={hi} deg: \
         its soft range ({}..={} deg), at least {STOP_AT_END_MARGIN_DEG} deg inside the \
         ±{} deg angle range",
        r.id,
        r.bus,
        soft.min_deg,
        soft.max_deg,
        units::MAX_ANGLE_DEG
    ));
    Err(err)
}

/// Homing job `id` as it stands.
pub(crate) fn get(state: &Control, id: u64) -> ControlResult<HomingView> {
    state
        .homings()
        .view(id)
        .ok_or_else(|| ControlError::not_found("unknown-homing", format!("no homing with id {id}")))
}

fn plan(req: &HomingRequest) -> ControlResult<Plan> {
    let within =
        |field: &str, v: Option<f64>, default: f64, (lo, hi): (f64, f64), open_low: bool| {
            let x = v.unwrap_or(default);
            let low_ok = if open_low { x > lo } else { x >= lo };
            if x.is_finite() && low_ok && x <= hi {
                Ok(x)
            } else {
                let unit = match field {
                    "speed_dps" => "deg/s",
                    "current_limit_a" => "A",
                    "timeout_ms" => "ms",
                    _ => "deg",
                };
                Err(ControlError::out_of_range(field, x, (lo, hi), unit))
            }
        };
    let max_a = units::current_limit_a(u16::MAX >> 1);
    Ok(Plan {
        direction: req.direction.unwrap_or_default(),
        speed_dps: within("speed_dps", req.speed_dps, 10.0, (0.0, 90.0), true)?,
        current_limit_a: within(
            "current_limit_a",
            req.current_limit_a,
            0.3,
            (0.0, max_a),
            true,
        )?,
        backoff_deg: within("backoff_deg", req.backoff_deg, 2.0, (0.0, 30.0), false)?,
        stop_at_deg: within(
            "stop_at_deg",
            req.stop_at_deg,
            0.0,
            (-units::MAX_ANGLE_DEG, units::MAX_ANGLE_DEG),
            false,
        )?,
        max_travel_deg: req
            .max_travel_deg
            .map(|d| within("max_travel_deg", Some(d), d, (0.0, MAX_TRAVEL_DEG), true))
            .transpose()?,
        timeout: Duration::from_secs_f64(
            within(
                "timeout_ms",
                req.timeout_ms,
                20_000.0,
                (0.0, 120_000.0),
                true,
            )? / 1e3,
        ),
    })
}

/// The joints named, or every joint of the hand; each once.
fn joints(state: &Control, req: &HomingRequest) -> ControlResult<Vec<JointRef>> {
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
            .hands()
            .and_then(|store| store.hand(hand))
            .ok_or_else(|| {
                ControlError::not_found("unknown-hand", format!("no hand named `{hand}`"))
            })?
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

/// Why a search ended without finding the stop.
enum Ended {
    Failed(String),
    Aborted(String),
}

fn set(slot: &Slot, edit: impl FnOnce(&mut JointHoming)) {
    edit(&mut lock(slot));
}

/// Homes one joint; whatever happens, its previous current limit is
/// written back (and read back) before the job says it ended.
/// A joint of a homing job and the motion epoch it was admitted under.
#[derive(Debug, Clone, Copy)]
struct Admitted {
    id: u8,
    epoch: Epoch,
}

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
    let limit = match units::current_limit_to_raw(plan.current_limit_a) {
        Ok(raw) if raw < previous => raw,
        _ => {
            let why = format!(
                "current_limit_a = {} A is not below the joint's own limit ({:.3} A): homing needs a reduced limit",
                plan.current_limit_a,
                units::current_limit_a(previous)
            );
            // Nothing was written: the limit just read is the previous one.
            set(&slot, |s| s.current_limit_restored = true);
            return finish(&slot, job, Err(Ended::Failed(why)));
        }
    };
    bus.take_over(&[id]);
    let mut guard = SpeedZero {
        bus: bus.clone(),
        id,
        armed: false,
    };
    let outcome = match bus.write_config(id, ConfigParam::MaxCur(limit)).await {
        Ok(_) => {
            set(&slot, |s| s.phase = "searching");
            guard.armed = true;
            search(&bus, joint, &plan, &soft, &mut events).await
        }
        Err(e) => Err(Ended::Failed(format!(
            "could not reduce the current limit: {e}"
        ))),
    };
    if guard.armed {
        // Stop pushing and leave speed mode, however the search ended.
        hold_here(&bus, id).await;
        guard.armed = false;
    }
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

/// Writes speed 0 (holding where the joint is) if the task leaves the
/// search without [`hold_here`] having done it: a panic unwinding.
struct SpeedZero {
    bus: BusHandle,
    id: u8,
    armed: bool,
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
async fn speed_zero_on_wire(bus: &BusHandle, id: u8) -> bool {
    match speed_zero(bus, id) {
        Some(seq) => wait_on_wire(bus, seq).await,
        None => false,
    }
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

/// Where the search must end without a stop: the soft limit or the
/// travel limit in the search direction, whichever comes first.
#[derive(Debug, Clone, Copy)]
struct Bound {
    /// Device degrees.
    deg: f64,
    /// Where the search started, device degrees.
    start_deg: f64,
    /// The soft limit (not the travel) is the nearer.
    soft: bool,
    travel_deg: f64,
}

impl Bound {
    fn new(plan: &Plan, soft: &JointLimits, start_deg: f64) -> Self {
        let travel_deg = plan.max_travel_deg.unwrap_or(soft.max_deg - soft.min_deg);
        let (by_travel, by_soft) = match plan.direction {
            Direction::Negative => (start_deg - travel_deg, soft.min_deg),
            Direction::Positive => (start_deg + travel_deg, soft.max_deg),
        };
        let soft_nearer = plan.direction.sign() * (by_travel - by_soft) >= 0.0;
        Self {
            deg: if soft_nearer { by_soft } else { by_travel },
            start_deg,
            soft: soft_nearer,
            travel_deg,
        }
    }

    /// The joint at `deg`, moving at `speed_dps` the search's way, is at
    /// the bound (or would pass it before speed 0 reaches it).
    fn reached(&self, dir: Direction, deg: f64, speed_dps: f64) -> bool {
        let ahead = speed_dps * BOUND_LOOKAHEAD.as_secs_f64();
        dir.sign() * (self.deg - deg) <= ahead
    }

    fn failure(&self, deg: f64) -> Ended {
        let what = if self.soft {
            format!(
                "the soft limits: the joint reached {deg:.1}° at its soft limit ({:.1}°), \
                 {:.1}° from where it started",
                self.deg,
                (deg - self.start_deg).abs()
            )
        } else {
            format!(
                "max_travel_deg = {}°: the joint reached {deg:.1}° from {:.1}°",
                self.travel_deg, self.start_deg
            )
        };
        Ended::Failed(format!("no hard stop within {what}"))
    }
}

/// Speed mode towards the stop until the joint stalls there; its angle.
/// Ends (failed) at the soft limit or after `max_travel_deg`.
async fn search(
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
        return Err(bound.failure(start_deg));
    }
    let rpm = plan.direction.sign() * plan.speed_dps / units::output_deg_per_s(1.0);
    let spd_ref = units::speed_to_raw(rpm, firmware_of(dev))
        .map_err(|e| Ended::Failed(format!("speed_dps: {e}")))?;
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
    let started = Instant::now();
    let deadline = started + plan.timeout;
    let mut watch = bus.watch();
    let mut last_sample: Option<Instant> = None;
    let mut moved = false;
    let mut stalled_since: Option<Instant> = None;
    loop {
        aborted_by_event(bus, events)?;
        revoked(bus, id, epoch)?;
        let snap = watch.borrow_and_update().clone();
        let dev = snap.devices.get(&id);
        unfit(dev)?;
        if let Some(deg) = dev.and_then(measured_angle_raw).map(units::angle_deg) {
            if bound.reached(plan.direction, deg, plan.speed_dps) {
                return Err(bound.failure(deg));
            }
        }
        if let Some((info, at)) = dev.and_then(|d| d.info02.as_ref().map(|(i, at)| (*i, *at))) {
            if last_sample.map_or(true, |last| at > last) && at >= started {
                last_sample = Some(at);
                let fw = dev.map(firmware_of).unwrap_or_default();
                let speed = units::output_deg_per_s(info.speed_rpm(fw)).abs();
                let current = units::current_a(info.q_cur).abs();
                moved |= speed > MOVING_SPEED_SHARE * plan.speed_dps;
                let slow = speed < STALLED_SPEED_SHARE * plan.speed_dps;
                let pushing = slow && current >= PUSHING_CURRENT_SHARE * plan.current_limit_a;
                let still = slow && (moved || at.duration_since(started) > START_GRACE);
                if pushing || still {
                    let since = *stalled_since.get_or_insert(at);
                    if at.duration_since(since) >= STALL_CONFIRM {
                        return Ok(units::angle_deg(info.angle));
                    }
                } else {
                    stalled_since = None;
                }
            }
        }
        let now = Instant::now();
        if now >= deadline {
            return Err(Ended::Failed(format!(
                "no stop found within {} ms (moved: {moved})",
                plan.timeout.as_millis()
            )));
        }
        let wait = (deadline - now).min(Duration::from_millis(20));
        let _ = tokio::time::timeout(wait, watch.changed()).await;
    }
}

/// An e-stop on the joint's bus ends the search (checked between samples,
/// and the joint's own state tells it too).
fn aborted_by_event(
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

/// Stops pushing and goes back to position mode: speed 0 (holding where
/// the joint is) on the wire first, then the mode. After an e-stop too:
/// speed 0 moves nothing, and a disabled joint keeps no speed for later.
async fn hold_here(bus: &BusHandle, id: u8) {
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

/// Off the stop by `backoff_deg`, slowly, in position mode; waits (a
/// little) until it is there. An e-stop meanwhile leaves it where it is;
/// a goal outside the soft limits is not sent.
async fn back_off(
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
