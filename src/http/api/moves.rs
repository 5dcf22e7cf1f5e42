//! REST of moves: start, read, stop (the logic is in [`crate::control::moves`],
//! shared with the WebSocket's `move` message).

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::moves::{self, MoveRequest, MoveView};
use crate::http::error::ApiResult;
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(start_move))
        .routes(routes!(get_move, stop_move))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct MovePath {
    /// The move's id, as `POST /api/v1/moves` answered it.
    #[param(example = 1)]
    pub id: u64,
}

/// Start a move of several joints (possibly on several buses) along one
/// path generated in the daemon.
///
/// All joints leave together and arrive together. The daemon streams the
/// path's positions at each bus's control rate through the same path as
/// setpoints. The whole path is checked against the soft limits first: a
/// path that leaves one is refused whole (422). A joint already following
/// a move leaves it for this one (`took_over_from`). An e-stop aborts the
/// move, and so does a joint going offline or faulting. A later target or
/// move on a joint takes it out of this move.
#[utoipa::path(post, path = "/api/v1/moves", tag = TAG_CONTROL,
    request_body(content = MoveRequest, example = json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 30.0},
        {"bus": "sim0", "id": 2, "position_deg": -20.0}], "duration_ms": 800, "method": "min_jerk"})),
    responses((status = 201, description = "Move started", body = MoveView), ErrorResponses))]
async fn start_move(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<MoveRequest>,
) -> ApiResult<(StatusCode, Json<MoveView>)> {
    Ok((
        StatusCode::CREATED,
        Json(moves::start(state.control(), &req).await?),
    ))
}

/// A move's state and progress.
///
/// Running, done (every joint arrived), stopped by `DELETE`, or aborted
/// with its reason (an e-stop, a joint offline or faulted).
#[utoipa::path(get, path = "/api/v1/moves/{id}", tag = TAG_CONTROL, params(MovePath),
    responses((status = 200, description = "The move", body = MoveView), ErrorResponses))]
async fn get_move(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<MovePath>,
) -> ApiResult<Json<MoveView>> {
    Ok(Json(moves::get(state.control(), p.id)?))
}

/// Stop a move: every joint holds where the path had brought it.
///
/// The joints keep the last position the path gave them; nothing else is
/// sent. Stopping a move that already ended answers its final state.
#[utoipa::path(delete, path = "/api/v1/moves/{id}", tag = TAG_CONTROL, params(MovePath),
    responses((status = 200, description = "The move, stopped (or as it ended)", body = MoveView), ErrorResponses))]
async fn stop_move(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<MovePath>,
) -> ApiResult<Json<MoveView>> {
    Ok(Json(moves::stop(state.control(), p.id)?))
}
