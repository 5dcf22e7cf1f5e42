//! The HTTP layer: one axum application over the control core, built in
//! one place ([`app`]). Handlers never touch a bus: they parse, call the
//! core ([`crate::control::Control`]), which checks and acts, and shape its
//! answer; what they read of a bus they read through a read-only
//! [`crate::control::bus_reader::BusReader`].
//!
//! The three areas below ([`api`], [`ws`], [`web`]) never import each
//! other: what two of them need lives here, beside them, so every import
//! points down or sideways into these shared files.
//!
//! # Layout
//! - [`api`]: the REST areas (buses, devices, control, config, e-stop, health) and the OpenAPI document.
//! - [`ws`]: the WebSocket endpoint: telemetry streams, setpoint batches, teleop watchdog.
//! - [`web`]: the embedded dashboard (or `--web-dir` while developing).
//! - [`state`]: [`AppState`]: the control core the daemon shares with ROS 2
//!   ([`crate::control::Control`]) and what only HTTP needs: token, WebSocket hub,
//!   host/origin policy; path parameters.
//! - [`error`]: [`ApiError`], RFC 9457 problem details; the one place that picks HTTP statuses.
//! - [`extract`]: JSON/path/query extractors whose rejections are problems.
//! - [`guard`]: the request guards before auth: Host (DNS rebinding), body size, browser origin.
//! - [`policy`]: what the guards decide, as pure functions: allow-lists, same-origin, body limit.
//! - [`auth`]: the bearer-token middleware (everything but the public paths).
//! - [`shed`]: load shedding: a bounded number of requests at once, e-stop exempt.
//! - [`paths`]: the URLs outside the OpenAPI routes, and which need no token.
//! - [`request_stats`]: answered requests by route template and status class, for `/metrics`.
//! - [`telemetry`]: snapshot → physical-unit views (REST and WebSocket).
//! - [`hub`]: what all WebSocket connections share (the state holds it).

pub mod api;
pub(crate) mod auth;
pub(crate) mod error;
pub(crate) mod extract;
pub(crate) mod guard;
pub(crate) mod hub;
pub(crate) mod paths;
pub mod policy;
pub(crate) mod request_stats;
pub mod scope;
pub mod serve;
pub(crate) mod shed;
pub mod state;
pub(crate) mod telemetry;
pub mod tokens;
pub(crate) mod web;
pub mod ws;

use axum::extract::DefaultBodyLimit;
use axum::Router;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::trace::TraceLayer;

pub use error::{ApiError, Problem};
pub use state::AppState;

/// The whole HTTP application. Tests call it with `oneshot` or serve it on
/// `127.0.0.1:0`; the daemon serves it on `--listen`. Set the state's
/// options first: the body limit is read here.
/// `listener` with TCP_NODELAY on every connection it accepts. Replies are
/// small and many (acks, pongs, telemetry): with Nagle's algorithm one
/// waits behind the previous one's delayed ACK, up to 40 ms on Linux (seen
/// as WebSocket round trips of 44 ms at p99 where p50 was 0.12 ms).
pub fn without_nagle(
    listener: tokio::net::TcpListener,
) -> impl axum::serve::Listener<Io = tokio::net::TcpStream, Addr = std::net::SocketAddr> {
    axum::serve::ListenerExt::tap_io(listener, |tcp| {
        if let Err(e) = tcp.set_nodelay(true) {
            tracing::warn!("TCP_NODELAY not set on a connection: {e}");
        }
    })
}

pub fn app(state: AppState) -> Router {
    let (router, doc) = api::router().split_for_parts();
    let router = router
        .merge(api::openapi::docs(doc))
        .merge(ws::router())
        .merge(web::router())
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::require_token,
        ))
        // Outside auth: a foreign page or host learns nothing, not even 401.
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            guard::check,
        ));
    // Only with allowed_origins: otherwise no origin but the daemon's own
    // may read an answer, and OPTIONS stays an unsupported method.
    let router = match cors(state.policy()) {
        Some(layer) => router.layer(layer),
        None => router,
    };
    router
        .layer(DefaultBodyLimit::max(state.policy().max_body_bytes))
        .layer(CatchPanicLayer::custom(panic_to_problem))
        // Before auth, guards and body reading: a shed request costs little.
        .layer(axum::middleware::from_fn_with_state(
            shed::InFlight::new(shed::MAX_IN_FLIGHT),
            shed::shed,
        ))
        .layer(axum::middleware::from_fn(log_failures))
        // Spans only: a failed answer is logged once, collapsed, below.
        .layer(TraceLayer::new_for_http().on_failure(()))
        // Outermost: shed, refused and unauthorised answers count too.
        .layer(axum::middleware::from_fn_with_state(
            state.requests().clone(),
            request_stats::count,
        ))
        .with_state(state)
}

/// How often the same failed answer (status and problem type) is logged.
const FAILURE_LOG_WINDOW: std::time::Duration = std::time::Duration::from_secs(10);

/// Server errors answered, collapsed per status and problem type.
static FAILURES: std::sync::LazyLock<crate::logcap::Collapse> =
    std::sync::LazyLock::new(|| crate::logcap::Collapse::new(FAILURE_LOG_WINDOW));

/// Logs a 5xx answer: a client retrying against a bus that is down must not
/// flood the log. Upstream failures (bus down or busy, device timeout) are
/// the client's to see and the bus log's to explain: WARN, one line per
/// kind per window with how many were held back. A 500 is a bug: ERROR.
async fn log_failures(
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    let path = req.uri().path().to_owned();
    let resp = next.run(req).await;
    if resp.status().is_server_error() {
        log_failure(&resp, &path);
    }
    resp
}

fn log_failure(resp: &axum::response::Response, path: &str) {
    let status = resp.status().as_u16();
    let problem = resp
        .extensions()
        .get::<error::ProblemType>()
        .map_or("-", |p| p.0.as_str());
    let key = format!("{status} {problem}");
    let Some(held) = FAILURES.admit(&key, std::time::Instant::now()) else {
        return;
    };
    let again = FAILURES.held_note(held);
    if status == 500 {
        tracing::error!(status, problem, path, "answered a server error{again}");
    } else {
        tracing::warn!(status, problem, path, "answered {status}{again}");
    }
}

/// CORS for the configured `allowed_origins` (a dashboard served
/// elsewhere): preflights answered, answers readable, the token header allowed.
fn cors(policy: &policy::RequestPolicy) -> Option<CorsLayer> {
    use axum::http::{header, HeaderValue, Method};
    let origins: Vec<HeaderValue> = policy
        .allowed_origins
        .iter()
        .filter_map(|o| HeaderValue::from_str(o).ok())
        .collect();
    if origins.is_empty() {
        return None;
    }
    let methods = [
        Method::GET,
        Method::POST,
        Method::PUT,
        Method::PATCH,
        Method::DELETE,
    ];
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods(methods)
            .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE])
            .expose_headers([header::RETRY_AFTER, header::WWW_AUTHENTICATE])
            .max_age(CORS_MAX_AGE),
    )
}

/// How long a browser may cache a preflight answer.
const CORS_MAX_AGE: std::time::Duration = std::time::Duration::from_secs(600);

async fn not_found(uri: axum::http::Uri) -> ApiError {
    ApiError::not_found("unknown-route", format!("no resource at {}", uri.path()))
}

async fn method_not_allowed(method: axum::http::Method) -> ApiError {
    ApiError::method_not_allowed(&method)
}

/// A bug must still answer in the one error shape (and is logged).
fn panic_to_problem(_: Box<dyn std::any::Any + Send + 'static>) -> axum::response::Response {
    tracing::error!("request handler panicked");
    axum::response::IntoResponse::into_response(ApiError::internal())
}
