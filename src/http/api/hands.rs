//! Named hands (`[[hand]]`) and their poses: list them (with what was wrong
//! with the state file when the daemon started), save a pose (given or the
//! hand's current targets), read, delete, and go to one as a move generated
//! by the daemon (`http::moves`). Poses live in the state file.

use std::collections::BTreeMap;

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::moves::MoveView;
use crate::control::poses::{self, PoseTiming};
use crate::control::stream_book::{Driver, Driving};
use crate::hands::{pose, Hand, HandJoint, LoadNotes, Pose, StateStore};
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::AppState;
use crate::http::telemetry::commanded_or_measured_raw;
use crate::motion::Method;
use crate::protocol::units;

/// Longest pose name.
const MAX_POSE_NAME: usize = 64;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_hands))
        .routes(routes!(get_pose, put_pose, delete_pose))
        .routes(routes!(go_to_pose))
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct HandList {
    pub hands: Vec<HandView>,
    /// Where poses and calibrations are kept (`null`: no `state_dir`, in
    /// memory until the daemon stops).
    pub state_file: Option<StateFileView>,
}

/// The state file, and what was wrong with it when the daemon started.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct StateFileView {
    #[schema(example = "/var/lib/jointd/state.json")]
    pub path: String,
    /// The file could not be used (not JSON of the expected shape, or not
    /// readable) and was renamed beside; the daemon started without its
    /// poses and calibrations. `null`: it was used (or there was none).
    pub set_aside: Option<SetAsideView>,
    /// The file could neither be used nor set aside: it is left as it is and
    /// saving answers 503. `null`: saving works.
    #[schema(example = json!(null))]
    pub unusable: Option<String>,
    /// Calibrations of the file that could not be applied, dropped (those
    /// joints read uncalibrated); the rest of the file was kept.
    pub dropped_calibrations: Vec<DroppedCalibrationView>,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct SetAsideView {
    #[schema(example = "/var/lib/jointd/state.json.bad-20250102T030405Z")]
    pub moved_to: String,
    #[schema(example = "not a state file: EOF while parsing a value at line 1 column 0")]
    pub reason: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DroppedCalibrationView {
    #[schema(example = "sim0")]
    pub bus: String,
    /// The device id as the file has it.
    #[schema(example = "2")]
    pub id: String,
    #[schema(
        example = "offset_deg = 1e308 must be a finite angle within ±255° (the device's position range)"
    )]
    pub reason: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct HandView {
    #[schema(example = "left")]
    pub name: String,
    pub joints: Vec<HandJointView>,
    /// The names of its saved poses.
    #[schema(example = json!(["fist", "open"]))]
    pub poses: Vec<String>,
    /// Programs streaming setpoints to its joints now (a WebSocket client
    /// such as the LeRobot plugin, or ROS 2 joint commands), oldest first:
    /// each with the names of the joints it streams to.
    #[schema(example = json!([{"via": "websocket", "client": 3, "name": "lerobot-jointd",
        "since_ms": 1764072000000u64, "idle_ms": 4, "joints": ["index_mcp", "index_pip"]}]))]
    pub streamed_by: Vec<HandStreamView>,
}

/// A program streaming setpoints to some of a hand's joints.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct HandStreamView {
    #[serde(flatten)]
    pub driver: Driver,
    /// Unix ms when its streams began (it has had one live since).
    pub since_ms: u64,
    /// How long ago it last sent setpoints (to any joint), ms.
    pub idle_ms: u64,
    /// The hand's joints it streams to, by name, in the hand's order.
    #[schema(example = json!(["index_mcp", "index_pip"]))]
    pub joints: Vec<String>,
}

/// Who streams to which of `hand`'s joints, from every live stream.
fn hand_streams(hand: &Hand, driving: &[Driving]) -> Vec<HandStreamView> {
    driving
        .iter()
        .filter_map(|d| {
            let joints: Vec<String> = hand
                .joints
                .iter()
                .filter(|j| d.joints.iter().any(|r| r.bus == j.bus && r.id == j.id))
                .map(|j| j.name.clone())
                .collect();
            (!joints.is_empty()).then(|| HandStreamView {
                driver: d.driver.clone(),
                since_ms: d.since_ms,
                idle_ms: d.idle_ms,
                joints,
            })
        })
        .collect()
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct HandJointView {
    #[schema(example = "index_mcp")]
    pub name: String,
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 2)]
    pub id: u8,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct PosePath {
    /// The hand's name, as configured.
    #[param(example = "left")]
    pub hand: String,
    /// The pose's name (letters, digits, `_`, `-`; up to 64).
    #[param(example = "fist")]
    pub name: String,
}

/// A pose to save: joint angles by joint name, or the hand's current targets.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"positions_deg": {"sim0_1": 40.0, "sim0_2": 35.5}}))]
pub(crate) struct PoseRequest {
    /// Degrees by joint name (any subset of the hand's joints, each once).
    #[serde(default, deserialize_with = "pose::unique")]
    pub positions_deg: Option<BTreeMap<String, f64>>,
    /// Save where every joint of the hand is now (its last target, else its
    /// measured angle) instead.
    #[serde(default)]
    pub from_current: bool,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct PoseView {
    #[schema(example = "left")]
    pub hand: String,
    #[schema(example = "fist")]
    pub name: String,
    #[schema(example = json!({"sim0_1": 40.0, "sim0_2": 35.5}))]
    pub positions_deg: BTreeMap<String, f64>,
}

/// How to go to a pose.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"duration_ms": 800, "method": "min_jerk"}))]
pub(crate) struct GoRequest {
    #[schema(example = 800.0)]
    pub duration_ms: Option<f64>,
    pub max_velocity_dps: Option<f64>,
    pub max_acceleration_dps2: Option<f64>,
    pub method: Option<Method>,
}

/// The configured hands, their joints and the names of their saved poses.
///
/// A hand (`[[hand]]` in the config) names a set of joints, possibly on
/// several buses, each with a joint name. `state_file` says where poses and
/// calibrations are kept and what was wrong with the file when the daemon
/// started (a bad file is set aside, bad calibrations dropped).
#[utoipa::path(get, path = "/api/v1/hands", tag = TAG_CONTROL,
    responses((status = 200, description = "The hands", body = HandList), ErrorResponses))]
async fn list_hands(State(state): State<AppState>) -> ApiResult<Json<HandList>> {
    let driving = state.stream_book().driving();
    let hands = state
        .hands()
        .map(|store| {
            store
                .hands()
                .iter()
                .map(|h| HandView {
                    name: h.name.clone(),
                    joints: h.joints.iter().map(joint_view).collect(),
                    poses: store.poses(&h.name).into_keys().collect(),
                    streamed_by: hand_streams(h, &driving),
                })
                .collect()
        })
        .unwrap_or_default();
    let state_file = state.hands().and_then(|store| {
        let path = store.state_path()?;
        Some(state_file_view(&path, store.notes()))
    });
    Ok(Json(HandList { hands, state_file }))
}

fn state_file_view(path: &std::path::Path, notes: &LoadNotes) -> StateFileView {
    StateFileView {
        path: path.display().to_string(),
        set_aside: notes.set_aside.as_ref().map(|a| SetAsideView {
            moved_to: a.moved_to.display().to_string(),
            reason: a.reason.clone(),
        }),
        unusable: notes.unusable.clone(),
        dropped_calibrations: notes
            .dropped
            .iter()
            .map(|c| DroppedCalibrationView {
                bus: c.bus.clone(),
                id: c.id.clone(),
                reason: c.reason.clone(),
            })
            .collect(),
    }
}

fn joint_view(j: &HandJoint) -> HandJointView {
    HandJointView {
        name: j.name.clone(),
        bus: j.bus.clone(),
        id: j.id,
    }
}

/// A saved pose.
///
/// The joint angles of the pose by joint name.
#[utoipa::path(get, path = "/api/v1/hands/{hand}/poses/{name}", tag = TAG_CONTROL, params(PosePath),
    responses((status = 200, description = "The pose", body = PoseView), ErrorResponses))]
async fn get_pose(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<PosePath>,
) -> ApiResult<Json<PoseView>> {
    let (store, _) = hand(&state, &p.hand)?;
    let pose = pose(store, &p)?;
    Ok(Json(view(&p, pose)))
}

/// Save a pose (replacing one of the same name), in the state file.
///
/// Joint angles by joint name (any subset of the hand's joints, each within
/// its soft limits), or `from_current` for where the hand is now. Written to
/// the state file atomically before the answer: it survives a restart.
#[utoipa::path(put, path = "/api/v1/hands/{hand}/poses/{name}", tag = TAG_CONTROL, params(PosePath),
    request_body(content = PoseRequest, example = json!({"positions_deg": {"sim0_1": 40.0, "sim0_2": 35.5}})),
    responses((status = 200, description = "Pose saved", body = PoseView), ErrorResponses))]
async fn put_pose(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<PosePath>,
    ApiJson(req): ApiJson<PoseRequest>,
) -> ApiResult<Json<PoseView>> {
    let (store, hand) = hand(&state, &p.hand)?;
    check_pose_name(&p.name)?;
    let pose = match (req.positions_deg, req.from_current) {
        (Some(_), true) => {
            return Err(ApiError::invalid(
                "from_current",
                "give positions_deg or from_current, not both",
            ))
        }
        (Some(positions), false) => checked(&state, hand, positions)?,
        (None, true) => current(&state, hand)?,
        (None, false) => {
            return Err(ApiError::invalid(
                "positions_deg",
                "give positions_deg (degrees by joint name) or from_current: true",
            ))
        }
    };
    store
        .put(&p.hand, &p.name, pose.clone())
        .map_err(|e| ApiError::state_unwritable(format!("{e}; the pose was not saved")))?;
    tracing::info!(hand = %p.hand, pose = %p.name, joints = pose.len(), "pose saved");
    Ok(Json(view(&p, pose)))
}

/// Delete a saved pose.
///
/// Removed from the state file before the answer.
#[utoipa::path(delete, path = "/api/v1/hands/{hand}/poses/{name}", tag = TAG_CONTROL, params(PosePath),
    responses((status = 200, description = "Pose deleted; the pose as it was", body = PoseView), ErrorResponses))]
async fn delete_pose(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<PosePath>,
) -> ApiResult<Json<PoseView>> {
    let (store, _) = hand(&state, &p.hand)?;
    let pose = pose(store, &p)?;
    store
        .delete(&p.hand, &p.name)
        .map_err(|e| ApiError::state_unwritable(format!("{e}; the pose was not deleted")))?;
    Ok(Json(view(&p, pose)))
}

/// Go to a saved pose: a move of the pose's joints generated by the daemon.
///
/// The same as `POST /api/v1/moves` with the pose's joints and angles (soft
/// limits checked on the whole path, 201 with the move).
#[utoipa::path(post, path = "/api/v1/hands/{hand}/poses/{name}/go", tag = TAG_CONTROL, params(PosePath),
    request_body(content = GoRequest, example = json!({"duration_ms": 800, "method": "min_jerk"})),
    responses((status = 201, description = "Move started", body = MoveView), ErrorResponses))]
async fn go_to_pose(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<PosePath>,
    ApiJson(req): ApiJson<GoRequest>,
) -> ApiResult<(StatusCode, Json<MoveView>)> {
    let timing = PoseTiming {
        duration_ms: req.duration_ms,
        max_velocity_dps: req.max_velocity_dps,
        max_acceleration_dps2: req.max_acceleration_dps2,
        method: req.method,
    };
    let started = poses::go(&state, &p.hand, &p.name, timing).await?;
    Ok((StatusCode::CREATED, Json(started)))
}

fn hand<'a>(state: &'a AppState, name: &str) -> ApiResult<(&'a StateStore, &'a Hand)> {
    state
        .hands()
        .and_then(|store| store.hand(name).map(|h| (store, h)))
        .ok_or_else(|| ApiError::not_found("unknown-hand", format!("no hand named `{name}`")))
}

fn pose(store: &StateStore, p: &PosePath) -> ApiResult<Pose> {
    store.pose(&p.hand, &p.name).ok_or_else(|| {
        ApiError::not_found(
            "unknown-pose",
            format!("hand `{}` has no pose named `{}`", p.hand, p.name),
        )
    })
}

fn view(p: &PosePath, pose: Pose) -> PoseView {
    PoseView {
        hand: p.hand.clone(),
        name: p.name.clone(),
        positions_deg: pose,
    }
}

fn check_pose_name(name: &str) -> ApiResult<()> {
    let ok = !name.is_empty()
        && name.len() <= MAX_POSE_NAME
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        return Ok(());
    }
    Err(ApiError::invalid(
        "name",
        format!("pose name `{name}`: 1..={MAX_POSE_NAME} letters, digits, `_` or `-`"),
    ))
}

/// Angles given by joint name (calibrated frame): each joint of the hand,
/// a finite number within its calibrated range and soft limits.
fn checked(state: &AppState, hand: &Hand, positions: BTreeMap<String, f64>) -> ApiResult<Pose> {
    if positions.is_empty() {
        return Err(ApiError::invalid("positions_deg", "positions_deg is empty"));
    }
    for (name, deg) in &positions {
        let field = format!("positions_deg.{name}");
        let joint = hand.joint(name).ok_or_else(|| {
            let names: Vec<&str> = hand.joints.iter().map(|j| j.name.as_str()).collect();
            ApiError::invalid(
                &field,
                format!(
                    "hand `{}` has no joint `{name}` (it has {})",
                    hand.name,
                    names.join(", ")
                ),
            )
        })?;
        if !deg.is_finite() {
            return Err(ApiError::invalid(&field, "not a finite number"));
        }
        let who = format!("joint `{name}` ({} on bus `{}`)", joint.id, joint.bus);
        let cal = state.calibration(&joint.bus, joint.id);
        state
            .limits(&joint.bus, joint.id)
            .check_joint_position(&cal, &field, *deg, &who)?;
    }
    Ok(positions)
}

/// Where every joint of the hand is now: its last target, else its angle.
fn current(state: &AppState, hand: &Hand) -> ApiResult<Pose> {
    let mut pose = Pose::new();
    for j in &hand.joints {
        let bus = state.bus(&j.bus)?;
        let snap = bus.snapshot();
        let raw = snap
            .devices
            .get(&j.id)
            .and_then(commanded_or_measured_raw)
            .ok_or_else(|| {
                ApiError::conflict(
                    "no-position",
                    "Position unknown",
                    format!(
                        "joint `{}` ({} on bus `{}`) has not reported its angle",
                        j.name, j.id, j.bus
                    ),
                )
            })?;
        let cal = state.calibration(&j.bus, j.id);
        pose.insert(j.name.clone(), cal.to_joint(units::angle_deg(raw)));
    }
    Ok(pose)
}
