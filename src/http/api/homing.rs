//! REST of homing: start a job, read it (the routine is in
//! [`crate::control::homing`]).

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::books::homing::HomingView;
use crate::control::homing::{self, HomingRequest};
use crate::http::error::ApiResult;
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(start_homing))
        .routes(routes!(get_homing))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct HomingPath {
    /// The job's id, as `POST /api/v1/homing` answered it.
    #[param(example = 1)]
    pub id: u64,
}

/// Home joints: find each one's hard stop and record it as its calibration.
///
/// Opt-in, per joint or for every joint of a hand (`hand`). Each joint must
/// be enabled and done aligning (fsm `run`: 409 `not-aligned` while it
/// aligns after its first enable, when it stands still as if at a stop),
/// in position mode, and in no running homing job (409 `homing-running`
/// naming that job). `stop_at_deg` must lie within the joint's soft range
/// and at least 30° inside ±255° (422 with the allowed range). Per joint:
/// the current limit is read and a reduced one written (RAM only); speed 0
/// goes on the wire, then the joint turns slowly in speed mode towards its
/// stop until it stalls there (or pushes, its current near the reduced
/// limit); that angle becomes its calibration offset (the stop then reads
/// `stop_at_deg`, flip and range kept); speed 0, position mode, and it
/// backs off by `backoff_deg`. The search ends `failed` ("no hard stop
/// within ...", speed 0, nothing saved) at the soft limit in its direction
/// or after `max_travel_deg` (default: the soft range's width). The
/// previous current limit is written back whatever happens: found, failed,
/// e-stopped, faulted, offline; `current_limit_restored` is true only when
/// reading it back shows the previous limit. An e-stop aborts it at once.
/// Answers 202 at once; poll `GET /api/v1/homing/{id}`.
#[utoipa::path(post, path = "/api/v1/homing", tag = TAG_CONTROL,
    request_body(content = HomingRequest, example = json!({"joints": [{"bus": "sim0", "id": 1}],
        "direction": "negative", "speed_dps": 10.0, "current_limit_a": 0.3, "backoff_deg": 2.0})),
    responses((status = 202, description = "Homing started", body = HomingView), ErrorResponses))]
async fn start_homing(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<HomingRequest>,
) -> ApiResult<(StatusCode, Json<HomingView>)> {
    Ok((
        StatusCode::ACCEPTED,
        Json(homing::start(state.control(), &req).await?),
    ))
}

/// A homing job: each joint's state, phase and result.
///
/// `running` until every joint ended; each joint then says `homed` (with
/// the stop's device angle and the offset recorded), `failed` or `aborted`
/// (with the reason), and whether its current limit was restored.
#[utoipa::path(get, path = "/api/v1/homing/{id}", tag = TAG_CONTROL, params(HomingPath),
    responses((status = 200, description = "The homing job", body = HomingView), ErrorResponses))]
async fn get_homing(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<HomingPath>,
) -> ApiResult<Json<HomingView>> {
    Ok(Json(homing::get(state.control(), p.id)?))
}
