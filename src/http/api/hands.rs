//! Named hands (`[[hand]]`): list them with their joints, pose names and
//! who streams to them, and what was wrong with the state file when the
//! daemon started. Their poses: [`super::poses`].

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::books::streams::{Driver, Driving};
use crate::hands::{Hand, HandJoint, LoadNotes};
use crate::http::error::ApiResult;
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_hands))
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

/// The configured hands, their joints and the names of their saved poses.
///
/// A hand (`[[hand]]` in the config) names a set of joints, possibly on
/// several buses, each with a joint name. `state_file` says where poses and
/// calibrations are kept and what was wrong with the file when the daemon
/// started (a bad file is set aside, bad calibrations dropped).
#[utoipa::path(get, path = "/api/v1/hands", tag = TAG_CONTROL,
    responses((status = 200, description = "The hands", body = HandList), ErrorResponses))]
async fn list_hands(State(state): State<AppState>) -> ApiResult<Json<HandList>> {
    let driving = state.control().stream_book().driving();
    let hands = state
        .control()
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
    let state_file = state.control().hands().and_then(|store| {
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
