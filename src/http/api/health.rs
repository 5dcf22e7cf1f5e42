//! `/healthz` (the process is up), `/readyz` (every bus is up) and
//! `/metrics` (Prometheus text, written by [`super::metrics`]).

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_HEALTH};
use crate::http::error::{ApiError, ApiResult};
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(healthz))
        .routes(routes!(readyz))
        .routes(routes!(metrics))
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Health {
    #[schema(example = "ok")]
    pub status: &'static str,
    #[schema(example = "0.1.0")]
    pub version: &'static str,
    #[schema(example = 12.5)]
    pub uptime_s: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusReadiness {
    #[schema(example = "sim0")]
    pub bus: String,
    /// `opening`, `up` or `down`.
    #[schema(example = "up")]
    pub link: &'static str,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Readiness {
    #[schema(example = true)]
    pub ready: bool,
    pub buses: Vec<BusReadiness>,
}

/// The process is up (never needs a token).
///
/// Answers as long as the process runs, whatever the buses do; for a container's liveness probe.
/// Never needs a token and skips the Host check so probes from outside work.
#[utoipa::path(get, path = "/healthz", tag = TAG_HEALTH, security(()),
    responses((status = 200, description = "The process is up", body = Health)))]
async fn healthz(State(state): State<AppState>) -> Json<Health> {
    Json(Health {
        status: "ok",
        version: env!("CARGO_PKG_VERSION"),
        uptime_s: state.uptime_s(),
    })
}

/// Every configured bus is up (503 otherwise, with each bus's link state).
///
/// Ready means every configured bus has its port open and its owner running. A bus that is down
/// (device unplugged, port missing) makes it 503 with each bus's link state in `partial`; for a
/// readiness probe or a start-up script that waits for the hardware.
#[utoipa::path(get, path = "/readyz", tag = TAG_HEALTH,
    responses((status = 200, description = "Every bus is up", body = Readiness), ErrorResponses))]
async fn readyz(State(state): State<AppState>) -> ApiResult<Json<Readiness>> {
    let buses: Vec<BusReadiness> = state
        .control()
        .readers()
        .map(|b| BusReadiness {
            bus: b.name().to_owned(),
            link: b.snapshot().link.name(),
        })
        .collect();
    let down: Vec<&str> = buses
        .iter()
        .filter(|b| b.link != "up")
        .map(|b| b.bus.as_str())
        .collect();
    if down.is_empty() {
        return Ok(Json(Readiness { ready: true, buses }));
    }
    let detail = format!("bus(es) not up: {}", down.join(", "));
    let partial = serde_json::to_value(&buses).unwrap_or_default();
    Err(ApiError::not_ready(detail).with_partial(partial))
}

/// Prometheus text: bus counters, link state, per-joint gauges.
///
/// The Prometheus text exposition of every counter and gauge: frames per kind, CRC errors,
/// timeouts, collisions, queue depths, per-joint telemetry, WebSocket clients. Scrape it;
/// `docs/metrics.md` lists the families.
#[utoipa::path(get, path = "/metrics", tag = TAG_HEALTH,
    responses((status = 200, description = "Prometheus text exposition format",
        content_type = "text/plain", body = String,
        example = "# HELP jointd_bus_up 1 when the bus's serial port is open and its owner running.\n\
            # TYPE jointd_bus_up gauge\njointd_bus_up{bus=\"sim0\"} 1\n\
            # HELP jointd_bus_frames_rx_total Frames received with a good CRC.\n\
            # TYPE jointd_bus_frames_rx_total counter\njointd_bus_frames_rx_total{bus=\"sim0\"} 10432\n"),
        ErrorResponses))]
async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, super::metrics::PROMETHEUS_TEXT)],
        super::metrics::render(&state),
    )
}
