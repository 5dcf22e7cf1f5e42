//! The REST API: axum routers over the bus handles. Handlers never touch a
//! port; they validate, convert physical units to raw with
//! [`crate::protocol::units`], and call a [`BusHandle`].
//!
//! # Layout
//! - [`state`]: [`AppState`]: the bus handles by name, soft limits, token.
//! - [`error`]: [`error::ApiError`], RFC 9457 problem details, the status of every failure.
//! - [`extract`]: JSON/path/query extractors whose rejections are problems.
//! - [`auth`]: the bearer-token middleware (everything but `/healthz`).
//! - [`limits`]: per-joint soft limits from the config.
//! - [`telemetry`]: snapshot → physical-unit views shared by the areas below.
//! - [`buses`], [`devices`], [`control`], [`config`], [`estop`], [`health`]: one router per area.
//! - [`openapi`]: the generated OpenAPI document and its docs page.

pub mod auth;
pub mod buses;
pub mod config;
pub mod config_params;
pub mod config_schema;
pub mod control;
pub mod devices;
pub mod error;
pub mod estop;
pub mod extract;
pub mod health;
pub mod limits;
pub mod openapi;
pub mod state;
pub mod targets;
pub mod telemetry;

use axum::http::StatusCode;
use axum::Router;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::trace::TraceLayer;

pub use error::{ApiError, Problem};
pub use state::AppState;

use crate::bus::BusHandle;

/// Prefix of every versioned resource.
pub const API_PREFIX: &str = "/api/v1";

/// The whole HTTP application. Tests call it with `oneshot` or serve it on
/// `127.0.0.1:0`; the daemon serves it on `--listen`.
pub fn app(state: AppState) -> Router {
    let (router, doc) = openapi::router().split_for_parts();
    router
        .merge(openapi::docs(doc))
        .merge(crate::ws::router())
        .merge(crate::web::router())
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::require_token,
        ))
        .layer(CatchPanicLayer::custom(panic_to_problem))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

async fn not_found(uri: axum::http::Uri) -> ApiError {
    ApiError::not_found("unknown-route", format!("no resource at {}", uri.path()))
}

async fn method_not_allowed(method: axum::http::Method) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method-not-allowed",
        "Method not allowed",
        format!("{method} is not supported on this resource"),
    )
}

/// A bug must still answer in the one error shape (and is logged).
fn panic_to_problem(_: Box<dyn std::any::Any + Send + 'static>) -> axum::response::Response {
    tracing::error!("request handler panicked");
    axum::response::IntoResponse::into_response(ApiError::new(
        StatusCode::INTERNAL_SERVER_ERROR,
        "internal",
        "Internal error",
        "the request handler failed; see the daemon log",
    ))
}

/// Convenience for the daemon and tests: state from handles with no limits
/// and no token.
pub fn state_for(buses: Vec<BusHandle>) -> AppState {
    AppState::new(buses, limits::SoftLimits::default(), None)
}
