//! REST of recordings: start, list, read, stop, download (the recorder is
//! [`crate::record`]; the jobs and their book, `control::recordings` and
//! `control::recording_book`).

use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::books::recordings::RecordingView;
use crate::control::recordings::{self, RecordingRequest};
use crate::http::error::{ApiResult, Problem};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(start_recording, list_recordings))
        .routes(routes!(get_recording, stop_recording))
        .routes(routes!(recording_file))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct RecordingPath {
    /// The recording's id, as `POST /api/v1/recordings` answered it.
    #[param(example = 1)]
    pub id: u64,
}

/// An MCAP file's bytes (only its schema is used: the handler sends the
/// bytes themselves).
#[derive(Debug, ToSchema)]
#[schema(value_type = String, format = Binary)]
pub(crate) struct McapBytes(#[allow(dead_code)] Vec<u8>);

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct RecordingList {
    pub recordings: Vec<RecordingView>,
}

/// Start recording the buses to an MCAP file.
///
/// Channels per bus: `/BUS/joint_states` (`sensor_msgs/msg/JointState`, CDR:
/// rad, rad/s, effort = q current in A, one message per poll round),
/// `/jointd/BUS/frames` (every frame with its direction and wire time),
/// `/jointd/BUS/events` and `/jointd/BUS/setpoints` (JSON). Chunks are
/// zstd-compressed and closed every second: a kill loses at most the last.
/// Stops by itself after `duration_s`, or at `DELETE`. Each bus may be
/// named once (422 naming a repeated one); at most 4 run at once (409). A
/// file that cannot be made is 507 when the disk is full, else 503, and
/// leaves no file behind.
#[utoipa::path(post, path = "/api/v1/recordings", tag = TAG_CONTROL,
    request_body(content = RecordingRequest, example = json!({"duration_s": 5.0})),
    responses((status = 201, description = "Recording started", body = RecordingView),
        (status = 507, description = "No room on the disk (or quota, or file size limit) for the recording's file",
            body = Problem, content_type = "application/problem+json"),
        ErrorResponses))]
async fn start_recording(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<RecordingRequest>,
) -> ApiResult<(StatusCode, Json<RecordingView>)> {
    Ok((
        StatusCode::CREATED,
        Json(recordings::start(state.control(), &req).await?),
    ))
}

/// The recordings made since the daemon started.
///
/// Running and finished ones, each with its file name and the messages
/// written so far by topic.
#[utoipa::path(get, path = "/api/v1/recordings", tag = TAG_CONTROL,
    responses((status = 200, description = "The recordings", body = RecordingList), ErrorResponses))]
async fn list_recordings(State(state): State<AppState>) -> ApiResult<Json<RecordingList>> {
    Ok(Json(RecordingList {
        recordings: recordings::list(state.control()),
    }))
}

/// A recording: its state, file and message counts.
///
/// `recording`, `finished` (the file is complete) or `failed` (with the
/// error: the disk full, the file removed from the disk; the file keeps
/// what reached it before, and is removed if nothing did).
#[utoipa::path(get, path = "/api/v1/recordings/{id}", tag = TAG_CONTROL, params(RecordingPath),
    responses((status = 200, description = "The recording", body = RecordingView), ErrorResponses))]
async fn get_recording(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<RecordingPath>,
) -> ApiResult<Json<RecordingView>> {
    Ok(Json(recordings::get(state.control(), p.id)?))
}

/// Stop a recording: its last chunk, summary and footer are written.
///
/// Answers once the file is complete. Stopping one that already ended
/// answers its final state.
#[utoipa::path(delete, path = "/api/v1/recordings/{id}", tag = TAG_CONTROL, params(RecordingPath),
    responses((status = 200, description = "The recording, finished", body = RecordingView), ErrorResponses))]
async fn stop_recording(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<RecordingPath>,
) -> ApiResult<Json<RecordingView>> {
    Ok(Json(recordings::stop(state.control(), p.id).await?))
}

/// Download a finished recording's MCAP file.
///
/// The file as written (`application/octet-stream`); 409 while it still
/// records, 404 (`recording-file-removed`) when the file was removed from
/// the disk. Opens in Foxglove and with `ros2 bag play` (storage mcap).
#[utoipa::path(get, path = "/api/v1/recordings/{id}/file", tag = TAG_CONTROL, params(RecordingPath),
    responses((status = 200, description = "The MCAP file", content_type = "application/octet-stream",
        body = McapBytes, example = json!("MCAP bytes: 89 4D 43 41 50 30 0D 0A ...")), ErrorResponses))]
async fn recording_file(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<RecordingPath>,
) -> ApiResult<impl IntoResponse> {
    let (name, bytes) = recordings::file(state.control(), p.id).await?;
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        bytes,
    ))
}
