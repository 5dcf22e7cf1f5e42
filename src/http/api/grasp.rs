//! REST of grasping: start a hand's grasp, read it, release it, stop it
//! (the routine is in [`crate::control::grasp`]).

use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::Json;
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::books::grasps::GraspView;
use crate::control::grasp::{self, GraspRequest, ReleaseRequest};
use crate::http::error::ApiResult;
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(start_grasp))
        .routes(routes!(get_grasp))
        .routes(routes!(release_grasp))
        .routes(routes!(stop_grasp))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct HandPath {
    /// The hand's name, as configured.
    #[param(example = "right")]
    pub hand: String,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct GraspPath {
    /// The grasp's id, as `POST /api/v1/hands/{hand}/grasp` answered it.
    #[param(example = 1)]
    pub id: u64,
}

/// Grasp: close a hand's fingers until each feels contact, then hold with
/// a set current.
///
/// Every finger (default: every joint of the hand) must be enabled, in
/// position mode and in no other grasp (409 `grasp-running`) or homing.
/// Each finger's current limit is set to `hold_current_a` (RAM), written
/// and verified on every finger before any finger moves; then each closes
/// at `speed_dps` towards its closing limit (`close_to_deg`, else the
/// hand's pose `closed`, else the top of its allowed range; within the
/// soft limits, 422 otherwise) until its q current rises
/// `contact_threshold_a` over what it draws moving freely, or it stalls
/// (`holding`, with `contact_deg`), or it reaches the limit (`no_contact`).
/// A held object whose current falls is `lost` (and a `grasp_lost`
/// event). An e-stop, a disable, a reset or a mode change ends it
/// (`aborted`); the previous limit is written back and read back however
/// it ends (`current_limit_restored`). Answers 202 at once with the job's
/// address in `Location`; poll `GET /api/v1/grasps/{id}`.
#[utoipa::path(post, path = "/api/v1/hands/{hand}/grasp", tag = TAG_CONTROL, params(HandPath),
    request_body(content = GraspRequest, example = json!({"speed_dps": 30.0, "hold_current_a": 0.2,
        "joints": [{"joint": "index", "close_to_deg": 80.0}]})),
    responses((status = 202, description = "Grasp started", body = GraspView,
        headers(("Location" = String, description = "The grasp job: /api/v1/grasps/{id}"))),
        ErrorResponses))]
async fn start_grasp(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<HandPath>,
    ApiJson(req): ApiJson<GraspRequest>,
) -> ApiResult<(
    StatusCode,
    [(header::HeaderName, String); 1],
    Json<GraspView>,
)> {
    let view = grasp::start(state.control(), &p.hand, &req).await?;
    let location = format!("/api/v1/grasps/{}", view.id);
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(view),
    ))
}

/// A grasp: each finger's state, contact, contact angle and current.
///
/// `running` while any finger is under the grasp's control, then `done`.
#[utoipa::path(get, path = "/api/v1/grasps/{id}", tag = TAG_CONTROL, params(GraspPath),
    responses((status = 200, description = "The grasp", body = GraspView), ErrorResponses))]
async fn get_grasp(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<GraspPath>,
) -> ApiResult<Json<GraspView>> {
    Ok(Json(grasp::get(state.control(), p.id)?))
}

/// Release a grasp: open every finger still in it, restore the limits.
///
/// Each finger opens to the hand's pose `pose`, or by `open_deg` from where
/// it is, or (neither) back to where it started, within its limits (422
/// otherwise; nothing moves), at `speed_dps` (default: the closing speed);
/// then its previous current limit is written back and read back. Answers
/// once every finger ended (`released`, with `current_limit_restored`):
/// 200. With many such calls already waiting, or after the bound, it
/// answers at once, the release under way: 202 (`state` `running`; poll
/// `GET /api/v1/grasps/{id}`). 409 `grasp-ended` if the grasp already
/// ended. The body may be `{}`.
#[utoipa::path(post, path = "/api/v1/grasps/{id}/release", tag = TAG_CONTROL, params(GraspPath),
    request_body(content = ReleaseRequest, example = json!({"open_deg": 20.0})),
    responses((status = 200, description = "The grasp, released", body = GraspView),
        (status = 202, description = "The release under way; the grasp as it stands", body = GraspView),
        ErrorResponses))]
async fn release_grasp(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<GraspPath>,
    ApiJson(req): ApiJson<ReleaseRequest>,
) -> ApiResult<(StatusCode, Json<GraspView>)> {
    Ok(ended_or_under_way(
        grasp::release(state.control(), p.id, &req).await?,
    ))
}

/// Stop a grasp: every finger holds where it is; limits restored.
///
/// Answers once every finger ended (`stopped`, with
/// `current_limit_restored`): 200; with many such calls already waiting,
/// or after the bound, at once, the stop under way: 202. Stopping a grasp
/// that already ended answers its final state.
#[utoipa::path(post, path = "/api/v1/grasps/{id}/stop", tag = TAG_CONTROL, params(GraspPath),
    responses((status = 200, description = "The grasp, stopped (or as it ended)", body = GraspView),
        (status = 202, description = "The stop under way; the grasp as it stands", body = GraspView),
        ErrorResponses))]
async fn stop_grasp(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<GraspPath>,
) -> ApiResult<(StatusCode, Json<GraspView>)> {
    Ok(ended_or_under_way(
        grasp::stop(state.control(), p.id).await?,
    ))
}

/// 200 with a grasp that ended, 202 with one still under way.
fn ended_or_under_way(view: GraspView) -> (StatusCode, Json<GraspView>) {
    let status = if view.state == "running" {
        StatusCode::ACCEPTED
    } else {
        StatusCode::OK
    };
    (status, Json(view))
}
