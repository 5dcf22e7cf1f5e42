//! The request guards, in front of auth, in this order: the `Host` check
//! (DNS rebinding), the browser-origin check on everything that changes
//! something, the declared body size. The decisions are `policy`'s; this file reads the
//! headers, logs a refusal once per host or origin, and answers.

use axum::extract::{Request, State};
use axum::http::header::{CONTENT_LENGTH, HOST, ORIGIN};
use axum::http::HeaderMap;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::paths::{HEALTHZ_PATH, WS_PATH};
use super::policy::{changes_state, check_host, check_origin, BrowserHeaders};
use super::state::AppState;

const SEC_FETCH_SITE: &str = "sec-fetch-site";

pub(crate) async fn check(State(state): State<AppState>, req: Request, next: Next) -> Response {
    match refusal(&state, &req) {
        Some(err) => err.into_response(),
        None => next.run(req).await,
    }
}

fn refusal(state: &AppState, req: &Request) -> Option<ApiError> {
    let policy = state.policy();
    let headers = req.headers();
    let path = req.uri().path();
    let host = header(headers, HOST.as_str()).or_else(|| req.uri().authority().map(|a| a.as_str()));
    // Container and orchestrator probes reach /healthz by whatever name
    // their network gives the container; it tells nothing but "alive".
    if path != HEALTHZ_PATH {
        if let Err(e) = check_host(policy, host) {
            log_once(state, "host", host.unwrap_or_default(), path);
            return Some(e);
        }
    }
    if changes_state(req.method(), path == WS_PATH) {
        let browser = BrowserHeaders {
            host,
            origin: header(headers, ORIGIN.as_str()),
            fetch_site: header(headers, SEC_FETCH_SITE),
        };
        if let Err(e) = check_origin(policy, browser) {
            let from = browser.origin.or(browser.fetch_site).unwrap_or_default();
            log_once(state, "origin", from, path);
            return Some(e);
        }
    }
    // Declared too large: refused before a byte of it is read. (A chunked
    // body is cut off by axum's DefaultBodyLimit while it is read.)
    match declared_length(headers) {
        Some(len) if len > policy.max_body_bytes => {
            Some(ApiError::payload_too_large(Some(policy.max_body_bytes)))
        }
        _ => None,
    }
}

fn header<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

fn declared_length(headers: &HeaderMap) -> Option<usize> {
    header(headers, CONTENT_LENGTH.as_str())?
        .trim()
        .parse()
        .ok()
}

/// WARN the first time a host or origin is refused, DEBUG after.
fn log_once(state: &AppState, what: &'static str, value: &str, path: &str) {
    if state.refusals().first_time(&format!("{what} {value}")) {
        tracing::warn!(
            %what,
            value,
            path,
            "refused a request (further refusals of the same {what} are logged at DEBUG)"
        );
    } else {
        tracing::debug!(%what, value, path, "refused a request");
    }
}
