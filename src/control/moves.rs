//! Moves as REST and the WebSocket both start them: a request checked
//! whole (joints, soft limits on the whole path, speed limits, enabled
//! joints) and turned into a [`RunningMove`] the bus owners stream
//! ([`crate::motion`], [`crate::bus::motion`]); views, stop.

use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::bus::handle::DeviceState;
use crate::bus::motion::Follower;
use crate::bus::BusHandle;
use crate::control::books::moves::Booked;
use crate::control::device::{firmware_of, measured_angle_raw};
use crate::control::error::{ControlError, ControlResult};
use crate::control::handoff;
use crate::control::joints::known_device;
use crate::control::joints::JointRef;
use crate::control::lookup::resolve_joint;
use crate::control::state::Control;
use crate::control::targets::admit_positions;
use crate::hands::Calibration;
use crate::motion::{Method, MoveState, Path, RunningMove};
use crate::protocol::{units, CtrlMode};

/// Every joint of a move leaves this long after the request is accepted,
/// so that the owners of several buses start it at the same instant.
const START_DELAY: Duration = Duration::from_millis(5);
/// The longest move accepted.
const MAX_DURATION_MS: f64 = 600_000.0;
/// Joints in one move at most (16 per bus, several buses).
const MAX_JOINTS: usize = 64;
/// A joint's frames carry this much more than the path's peak speed as
/// their speed limit, so the device never lags the path for want of it.
const SPEED_HEADROOM: f64 = 1.25;
/// ... and at least this (rotor rpm): a slow path still gets a firm limit.
const MIN_SPEED_LIMIT_RPM: f64 = 500.0;

/// One joint and where it goes: by `bus` and `id`, or by `hand` and
/// `joint` (its name in a `[[hand]]` of the config).
#[derive(Debug, Clone, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct MoveJoint {
    #[schema(example = "sim0")]
    pub bus: Option<String>,
    #[schema(example = 1)]
    pub id: Option<i64>,
    /// A hand's name (with `joint`, instead of `bus` and `id`).
    pub hand: Option<String>,
    /// The joint's name in that hand.
    pub joint: Option<String>,
    /// Target, degrees (required unless `waypoints` are given).
    #[schema(example = 30.0)]
    pub position_deg: Option<f64>,
}

/// A waypoint: every joint's position, reached at `at_ms` after the start.
#[derive(Debug, Clone, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct WaypointRequest {
    #[schema(example = 400.0)]
    pub at_ms: f64,
    /// One position per joint, in the order of `joints`, degrees.
    #[schema(example = json!([20.0, -10.0]))]
    pub positions_deg: Vec<f64>,
}

/// A move of several joints, which leave together and arrive together.
#[derive(Debug, Clone, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 30.0},
    {"bus": "sim0", "id": 2, "position_deg": -20.0}], "duration_ms": 800, "method": "min_jerk"}))]
pub(crate) struct MoveRequest {
    pub joints: Vec<MoveJoint>,
    /// How long the move takes, ms (0 < d ≤ 600000). With velocity or
    /// acceleration limits as well, the longer of the two.
    #[schema(example = 800.0)]
    pub duration_ms: Option<f64>,
    /// The fastest any joint may turn, output degrees per second.
    #[schema(example = 180.0)]
    pub max_velocity_dps: Option<f64>,
    /// The largest acceleration of any joint, output degrees per second².
    #[schema(example = 2000.0)]
    pub max_acceleration_dps2: Option<f64>,
    /// The shape of the path (default `min_jerk`).
    pub method: Option<Method>,
    /// Instead of `position_deg`: positions at times (a whole grasp).
    pub waypoints: Option<Vec<WaypointRequest>>,
}

/// A move as the API reports it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct MoveView {
    #[schema(example = 1)]
    pub id: u64,
    pub state: MoveState,
    /// Why it was stopped or aborted.
    pub reason: Option<String>,
    pub method: Method,
    #[schema(example = 800.0)]
    pub duration_ms: f64,
    /// Share of its time gone, 0..=1.
    #[schema(example = 0.5)]
    pub progress: f64,
    pub joints: Vec<JointRef>,
    /// Joints a newer move or setpoint took over (they left this move).
    pub replaced: Vec<JointRef>,
    /// Joints that reached the end of the path.
    pub arrived: Vec<JointRef>,
    /// Joints that could not follow the path (blocked): each holds where it stood.
    pub stalled: Vec<JointRef>,
    /// Running moves this one took joints from, when it started (each
    /// goes on with its other joints).
    pub took_over_from: Vec<u64>,
}

/// Checks `req` whole and starts the move; its view, with the moves it
/// took joints from.
pub(crate) async fn start(state: &Control, req: &MoveRequest) -> ControlResult<MoveView> {
    let plan = plan(state, req)?;
    // Each joint's motion epoch now: the move drives it only while that
    // epoch lasts (an e-stop, disable, reset, fault, mode change or enable
    // from here on ends it).
    let mut epochs = Vec::new();
    for (bus, joints) in &plan.by_bus {
        let snap = bus.snapshot();
        let mut on_bus = Vec::with_capacity(joints.len());
        for (_, dev_id, _) in joints {
            let dev = known_device(&snap, *dev_id)?;
            on_bus.push(admit_positions(bus, dev, "a move")?);
            ensure_running(bus, dev)?;
        }
        epochs.push(on_bus);
    }
    let id = state.moves().next_id();
    let grasped = handoff::pending(state, &plan.joints);
    let mv = Arc::new(if grasped.is_empty() {
        RunningMove::new(id, plan.path, Instant::now() + START_DELAY)
    } else {
        RunningMove::held(id, plan.path, Instant::now() + handoff::BOUND)
    });
    let mut took_over_from = Vec::new();
    for ((bus, joints), epochs) in plan.by_bus.iter().zip(&epochs) {
        let followers = joints
            .iter()
            .zip(epochs)
            .map(|((joint, dev_id, spd_ref), epoch)| {
                Follower::new(*dev_id, mv.clone(), *joint, *spd_ref, *epoch)
            })
            .collect();
        took_over_from.extend(bus.follow(followers));
    }
    took_over_from.sort_unstable();
    took_over_from.dedup();
    tracing::info!(move_id = id, joints = plan.joints.len(), duration_ms = mv.path.duration().as_millis() as u64,
        method = ?mv.path.method(), ?took_over_from, "move started");
    state.moves().insert(mv.clone(), plan.joints.clone());
    if !grasped.is_empty() {
        handoff::start_when_handed_back(mv.clone(), grasped, START_DELAY);
    }
    let mut view = view(&mv, &plan.joints);
    view.took_over_from = took_over_from;
    Ok(view)
}

/// Stops move `id` (its joints hold where they are); its view.
pub(crate) fn stop(state: &Control, id: u64) -> ControlResult<MoveView> {
    let booked = booked(state, id)?;
    if booked.mv.end(MoveState::Stopped, "stopped by its caller") {
        tracing::info!(move_id = id, "move stopped by its caller");
        let mut buses: Vec<&str> = booked.joints.iter().map(|j| j.bus.as_str()).collect();
        buses.dedup();
        for name in buses {
            if let Ok(bus) = state.bus(name) {
                bus.move_stopped(id);
            }
        }
    }
    Ok(view(&booked.mv, &booked.joints))
}

/// Move `id` as it stands.
pub(crate) fn get(state: &Control, id: u64) -> ControlResult<MoveView> {
    let booked = booked(state, id)?;
    Ok(view(&booked.mv, &booked.joints))
}

/// 409 while the joint aligns after its first enable: it stands still
/// until it runs, and a path started meanwhile would leave it behind.
fn ensure_running(bus: &BusHandle, dev: &DeviceState) -> ControlResult<()> {
    match dev.info01.as_ref() {
        Some((info, _)) if info.fsm == crate::protocol::status::fsm::ALIGN => {
            Err(ControlError::conflict(
                "not-enabled",
                "Joint still aligning",
                format!(
                    "a move needs joint {} of bus `{}` running; it is aligning after its \
                     enable (wait until its state is `run`)",
                    dev.dev_id,
                    bus.name()
                ),
            ))
        }
        _ => Ok(()),
    }
}

fn booked(state: &Control, id: u64) -> ControlResult<Booked> {
    state
        .moves()
        .get(id)
        .ok_or_else(|| ControlError::not_found("unknown-move", format!("no move with id {id}")))
}

fn view(mv: &RunningMove, joints: &[JointRef]) -> MoveView {
    let status = mv.status();
    let pick = |idx: &[usize]| idx.iter().filter_map(|i| joints.get(*i).cloned()).collect();
    MoveView {
        id: mv.id,
        state: status.state,
        reason: status.reason,
        method: mv.path.method(),
        duration_ms: mv.path.duration().as_secs_f64() * 1e3,
        progress: if status.state == MoveState::Done {
            1.0
        } else {
            mv.progress(Instant::now())
        },
        joints: joints.to_vec(),
        replaced: pick(&status.replaced),
        arrived: pick(&status.arrived),
        stalled: pick(&status.stalled),
        took_over_from: Vec::new(),
    }
}

/// A joint on its bus: its index in the path, its id, the speed limit its
/// frames carry (raw).
type OnBus = (usize, u8, i16);

/// A request checked and turned into a path, its joints grouped by bus.
struct Plan<'a> {
    path: Path,
    joints: Vec<JointRef>,
    by_bus: Vec<(&'a BusHandle, Vec<OnBus>)>,
}

fn plan<'a>(state: &'a Control, req: &MoveRequest) -> ControlResult<Plan<'a>> {
    if req.joints.is_empty() || req.joints.len() > MAX_JOINTS {
        return Err(ControlError::invalid(
            "joints",
            format!(
                "a move needs 1..={MAX_JOINTS} joints, got {}",
                req.joints.len()
            ),
        ));
    }
    let method = req.method.unwrap_or_default();
    let mut joints: Vec<JointRef> = Vec::with_capacity(req.joints.len());
    let mut start = Vec::with_capacity(req.joints.len());
    for (i, j) in req.joints.iter().enumerate() {
        let r = joint_ref(state, i, j)?;
        let (bus, id) = (state.bus(&r.bus)?, r.id);
        if joints.contains(&r) {
            return Err(ControlError::duplicate(
                &format!("joints[{i}]"),
                format!("joint {id} of bus `{}` appears twice", r.bus),
            ));
        }
        let snap = bus.snapshot();
        let dev = known_device(&snap, id)?;
        if dev.mode.is_some_and(|m| m != CtrlMode::Position) {
            return Err(ControlError::conflict(
                "wrong-mode",
                "Joint not in position mode",
                format!(
                    "joint {id} of bus `{}` is not in position mode: a move needs position mode",
                    r.bus
                ),
            ));
        }
        // From where the joint is, never from a target it has not
        // reached: a path from the target would first turn it towards a
        // goal it was just taken away from (or, out of a grasp, further
        // into the object).
        let from = measured_angle_raw(dev).ok_or_else(|| {
            ControlError::conflict(
                "no-position",
                "Position unknown",
                format!(
                    "joint {id} of bus `{}` has not reported its angle yet",
                    r.bus
                ),
            )
        })?;
        start.push(units::angle_deg(from));
        joints.push(r);
    }
    let cals: Vec<Calibration> = joints
        .iter()
        .map(|r| state.calibration(&r.bus, r.id))
        .collect();
    let waypoints = to_device_frame(waypoints(req)?, &cals);
    let path = timed_path(req, method, start, waypoints)?;
    check_limits(state, &joints, &cals, &path)?;
    let mut by_bus: Vec<(&BusHandle, Vec<OnBus>)> = Vec::new();
    for (i, r) in joints.iter().enumerate() {
        let bus = state.bus(&r.bus)?;
        let spd_ref = speed_limit(state, bus, r, path.peak_velocity_of(i))?;
        match by_bus.iter_mut().find(|(b, _)| b.name() == r.bus) {
            Some((_, list)) => list.push((i, r.id, spd_ref)),
            None => by_bus.push((bus, vec![(i, r.id, spd_ref)])),
        }
    }
    Ok(Plan {
        path,
        joints,
        by_bus,
    })
}

/// A joint named by bus and id, or by hand and joint name.
fn joint_ref(state: &Control, i: usize, j: &MoveJoint) -> ControlResult<JointRef> {
    resolve_joint(
        state,
        &format!("joints[{i}]"),
        j.bus.as_deref(),
        j.id,
        j.hand.as_deref(),
        j.joint.as_deref(),
    )
}

/// The request's waypoints, or its targets as the one waypoint (time to be set).
fn waypoints(req: &MoveRequest) -> ControlResult<Vec<(Option<f64>, Vec<f64>)>> {
    match &req.waypoints {
        Some(list) => {
            if let Some(i) = req.joints.iter().position(|j| j.position_deg.is_some()) {
                return Err(ControlError::invalid(
                    &format!("joints[{i}].position_deg"),
                    "give either waypoints or each joint's position_deg, not both",
                ));
            }
            if list.is_empty() {
                return Err(ControlError::invalid("waypoints", "waypoints is empty"));
            }
            // Each waypoint says when it is reached: a duration would be
            // ignored, and a caller who gave one expects it to count.
            for (field, given) in [
                ("duration_ms", req.duration_ms.is_some()),
                ("max_velocity_dps", req.max_velocity_dps.is_some()),
                ("max_acceleration_dps2", req.max_acceleration_dps2.is_some()),
            ] {
                if given {
                    return Err(ControlError::invalid(
                        field,
                        format!(
                            "{field} does not apply to waypoints: each waypoint's at_ms times it"
                        ),
                    ));
                }
            }
            Ok(list
                .iter()
                .map(|w| (Some(w.at_ms), w.positions_deg.clone()))
                .collect())
        }
        None => {
            let mut target = Vec::with_capacity(req.joints.len());
            for (i, j) in req.joints.iter().enumerate() {
                let deg = j.position_deg.ok_or_else(|| {
                    ControlError::invalid(
                        &format!("joints[{i}].position_deg"),
                        "position_deg is required (or give waypoints)",
                    )
                })?;
                target.push(deg);
            }
            Ok(vec![(None, target)])
        }
    }
}

fn positive(field: &str, v: Option<f64>, max: f64) -> ControlResult<Option<f64>> {
    match v {
        Some(x) if !(x.is_finite() && x > 0.0 && x <= max) => Err(ControlError::out_of_range(
            field,
            x,
            (0.0, max),
            if field.ends_with("_ms") { "ms" } else { "" },
        )),
        other => Ok(other),
    }
}

/// The path in time: waypoint times as given, or the duration asked and
/// whatever the velocity and acceleration limits need (the longer).
fn timed_path(
    req: &MoveRequest,
    method: Method,
    start: Vec<f64>,
    waypoints: Vec<(Option<f64>, Vec<f64>)>,
) -> ControlResult<Path> {
    let duration = positive("duration_ms", req.duration_ms, MAX_DURATION_MS)?;
    let vmax = positive("max_velocity_dps", req.max_velocity_dps, 1e6)?;
    let amax = positive("max_acceleration_dps2", req.max_acceleration_dps2, 1e9)?;
    let timed: Vec<(Duration, Vec<f64>)> = if let [(None, target)] = waypoints.as_slice() {
        let shortest = start
            .iter()
            .zip(target)
            .map(|(a, b)| method.shortest(b - a, vmax, amax))
            .fold(0.0, f64::max);
        let ms = match (duration, vmax.or(amax)) {
            (Some(d), _) => d.max(shortest * 1e3),
            (None, Some(_)) => (shortest * 1e3).max(1.0),
            (None, None) => {
                return Err(ControlError::invalid(
                    "duration_ms",
                    "give duration_ms, or max_velocity_dps / max_acceleration_dps2",
                ))
            }
        };
        if ms > MAX_DURATION_MS {
            return Err(ControlError::out_of_range(
                "duration_ms",
                ms,
                (0.0, MAX_DURATION_MS),
                "ms",
            ));
        }
        vec![(Duration::from_secs_f64(ms / 1e3), target.clone())]
    } else {
        let mut out = Vec::with_capacity(waypoints.len());
        for (i, (at, positions)) in waypoints.into_iter().enumerate() {
            let field = format!("waypoints[{i}].at_ms");
            let at = positive(&field, at, MAX_DURATION_MS)?.unwrap_or(0.0);
            out.push((Duration::from_secs_f64(at / 1e3), positions));
        }
        out
    };
    Path::new(method, start, timed).map_err(|e| ControlError::invalid("waypoints", e.to_string()))
}

/// Positions as given (each joint's calibrated frame) as device angles:
/// the path is planned and streamed in the device's frame. The map is
/// affine, so the path has the same shape and timing in both.
fn to_device_frame(
    mut waypoints: Vec<(Option<f64>, Vec<f64>)>,
    cals: &[Calibration],
) -> Vec<(Option<f64>, Vec<f64>)> {
    for (_, positions) in &mut waypoints {
        for (deg, cal) in positions.iter_mut().zip(cals) {
            *deg = cal.to_device(*deg);
        }
    }
    waypoints
}

/// Every position the path passes through within each joint's calibrated
/// range and soft limits (told in the joint's frame).
fn check_limits(
    state: &Control,
    joints: &[JointRef],
    cals: &[Calibration],
    path: &Path,
) -> ControlResult<()> {
    for ((i, r), cal) in joints.iter().enumerate().zip(cals) {
        let limits = state.limits(&r.bus, r.id);
        let who = format!("joint {} of bus `{}`", r.id, r.bus);
        for deg in path.extremes(i).skip(1) {
            let field = format!("joints[{i}].position_deg");
            limits.check_joint_position(cal, &field, cal.to_joint(deg), &who)?;
        }
    }
    Ok(())
}

/// The speed limit of a joint's frames: the path's peak with headroom,
/// within its soft limit (422 when the path needs more than it allows).
fn speed_limit(
    state: &Control,
    bus: &BusHandle,
    r: &JointRef,
    peak_dps: f64,
) -> ControlResult<i16> {
    let rpm_per_dps = 1.0 / units::output_deg_per_s(1.0);
    let needed = peak_dps * rpm_per_dps;
    let limits = state.limits(&r.bus, r.id);
    if let Some(max) = limits.max_speed_dps.filter(|max| peak_dps > *max) {
        return Err(ControlError::invalid(
            "duration_ms",
            format!(
                "the path needs {peak_dps:.1} °/s of joint {} of bus `{}`, its soft limit allows {max:.1} °/s: \
                 give the move more time or a lower max_velocity_dps",
                r.id, r.bus
            ),
        ));
    }
    let rpm = (needed * SPEED_HEADROOM).max(MIN_SPEED_LIMIT_RPM);
    let rpm = limits
        .max_speed_dps
        .map_or(rpm, |max| rpm.min(max * rpm_per_dps));
    let snap = bus.snapshot();
    let fw = snap.devices.get(&r.id).map(firmware_of).unwrap_or_default();
    let raw = units::speed_limit_to_raw(rpm, fw)
        .map_err(|e| ControlError::from_unit("duration_ms", e))?;
    // The wire's Q15 step is ~1.5 rpm: rounding must not carry the frames
    // past the limit they were capped at.
    Ok(if units::speed_rpm(raw, fw) > rpm && raw > 0 {
        raw - 1
    } else {
        raw
    })
}
