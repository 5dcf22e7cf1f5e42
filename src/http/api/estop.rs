//! Emergency stop: one call disables every device on every bus at once,
//! ahead of anything queued, and reports what it did: which devices read
//! back stopped, which needed a second disable, which could not be read.
//! Buses are stopped concurrently, not one after another.

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_ESTOP};
use crate::bus::BusHandle;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::ApiPath;
use crate::http::state::{AppState, BusPath};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(estop_all))
        .routes(routes!(estop_bus))
}

/// What the e-stop did on one bus.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct BusStop {
    #[schema(example = "sim0")]
    pub bus: String,
    /// True when every disable frame was written and no device read back
    /// still driving its motor.
    #[schema(example = true)]
    pub stopped: bool,
    /// Disable frames written (`0xFF` first, then one per known device).
    #[schema(example = 17)]
    pub frames_sent: u32,
    /// Queued requests failed because the e-stop went first.
    #[schema(example = 2)]
    pub preempted_requests: u32,
    /// From the call to the first disable frame handed to the port, µs.
    #[schema(example = 180)]
    pub latency_us: u64,
    /// Devices read back afterwards not driving their motor.
    #[schema(example = json!([1, 2, 3]))]
    pub confirmed: Vec<u8>,
    /// Devices read back still driving, which were sent their own disable
    /// again (each is then in `confirmed` or `still_enabled`).
    #[schema(example = json!([]))]
    pub disabled_again: Vec<u8>,
    /// Devices still driving after that second disable: NOT stopped.
    #[schema(example = json!([]))]
    pub still_enabled: Vec<u8>,
    /// Devices whose state could not be read back (offline or silent):
    /// they were sent the disables, but nothing confirms they stopped.
    #[schema(example = json!([]))]
    pub unconfirmed: Vec<u8>,
    /// Why this bus could not be stopped, if it could not.
    pub error: Option<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct EstopResult {
    #[schema(example = true)]
    pub stopped: bool,
    pub buses: Vec<BusStop>,
    /// Wall time of the whole call, µs.
    #[schema(example = 950)]
    pub elapsed_us: u64,
}

async fn stop_one(bus: BusHandle) -> BusStop {
    match bus.estop().await {
        Ok(r) => BusStop {
            bus: r.bus,
            stopped: r.still_enabled.is_empty(),
            frames_sent: r.frames_sent,
            preempted_requests: r.preempted_requests,
            latency_us: r.latency_us,
            error: (!r.still_enabled.is_empty()).then(|| {
                format!(
                    "device(s) {:?} still enabled after a second disable",
                    r.still_enabled
                )
            }),
            confirmed: r.confirmed,
            disabled_again: r.disabled_again,
            still_enabled: r.still_enabled,
            unconfirmed: r.unconfirmed,
        },
        Err(e) => BusStop {
            bus: bus.name().to_owned(),
            stopped: false,
            frames_sent: 0,
            preempted_requests: 0,
            latency_us: 0,
            error: Some(e.to_string()),
            confirmed: Vec::new(),
            disabled_again: Vec::new(),
            still_enabled: Vec::new(),
            unconfirmed: Vec::new(),
        },
    }
}

/// Stops the given buses concurrently; 503 (with every bus's result in
/// `partial`) unless all of them stopped.
async fn stop(buses: Vec<BusHandle>) -> ApiResult<Json<EstopResult>> {
    let started = Instant::now();
    // Polled here, in this request's task, not spawned: a spawned task
    // would wait for a worker behind whatever else is queued.
    let mut results = futures_util::future::join_all(buses.into_iter().map(stop_one)).await;
    results.sort_by(|a, b| a.bus.cmp(&b.bus));
    let result = EstopResult {
        stopped: results.iter().all(|r| r.stopped),
        elapsed_us: u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX),
        buses: results,
    };
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
    stop(state.buses().cloned().collect()).await
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
    let bus = state.bus(&p.bus)?.clone();
    stop(vec![bus]).await
}
