//! Emergency stop: one call disables every device on every bus at once,
//! ahead of anything queued, and reports what it did: which devices read
//! back stopped, which needed a second disable, which could not be read.
//! Buses are stopped concurrently, not one after another.

use axum::extract::State;
use axum::Json;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_ESTOP};
use crate::control::estop::EstopResult;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::ApiPath;
use crate::http::state::{AppState, BusPath};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(estop_all))
        .routes(routes!(estop_bus))
}

/// The e-stop's answer: 503 (with every bus's result in `partial`) unless
/// every bus confirmed its stop.
fn answer(result: EstopResult) -> ApiResult<Json<EstopResult>> {
    if result.stopped {
        return Ok(Json(result));
    }
    let failed: Vec<&str> = result
        .buses
        .iter()
        .filter(|b| !b.stopped)
        .map(|b| b.bus.as_str())
        .collect();
    Err(ApiError::estop_incomplete(format!(
        "could not confirm the stop of bus(es): {}",
        failed.join(", ")
    ))
    .with_partial(serde_json::to_value(&result).unwrap_or_default()))
}

/// Disable every device on every bus at once, ahead of anything queued.
///
/// Emergency stop: every bus sends CMD_DISABLE to all its devices ahead of any queued request and
/// confirms each device stopped. 503 with per-bus results in `partial` when a bus could not confirm
/// every device.
#[utoipa::path(post, path = "/api/v1/estop", tag = TAG_ESTOP,
    responses((status = 200, description = "Every bus stopped", body = EstopResult), ErrorResponses))]
async fn estop_all(State(state): State<AppState>) -> ApiResult<Json<EstopResult>> {
    answer(state.control().estop_all().await)
}

/// Disable every device on one bus, ahead of anything queued.
///
/// Emergency stop of one bus: CMD_DISABLE to all its devices ahead of any queued request, confirmed
/// per device. Other buses are not touched.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/estop", tag = TAG_ESTOP, params(BusPath),
    responses((status = 200, description = "The bus stopped", body = EstopResult), ErrorResponses))]
async fn estop_bus(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
) -> ApiResult<Json<EstopResult>> {
    answer(state.control().estop_buses(&[p.bus.as_str()]).await?)
}
