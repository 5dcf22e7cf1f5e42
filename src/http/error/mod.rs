//! One error shape for every failure: RFC 9457 problem details
//! (`application/problem+json`), and the one module that picks HTTP
//! statuses. Handlers return [`ApiResult`] and use `?` on bus errors; the
//! same device answer is then the same status on every route. The OpenAPI
//! document describes each status from [`DOCUMENTED_STATUSES`] below.
//!
//! | cause | status |
//! |---|---|
//! | malformed JSON, unparsable path or query | 400 |
//! | missing or wrong bearer token | 401 |
//! | a change (or the WebSocket) from a foreign browser origin | 403 |
//! | unknown bus, device or route | 404 |
//! | method not supported on the route | 405 |
//! | wrong state (jog while disabled), device refused (RES 0), preempted by e-stop | 409 |
//! | request body over `max_body_bytes` | 413 |
//! | JSON body not `application/json` | 415 |
//! | `Host` names no host of this daemon (DNS rebinding) | 421 |
//! | value out of range, soft limit, invalid field, body not of the schema | 422 |
//! | `GET /api/v1/ws` without a WebSocket upgrade | 426 |
//! | a bug (handler panicked) | 500 |
//! | device answered something other than what was asked, or reads back another value than written | 502 |
//! | bus down, request queue full, bus owner stopped, not ready, e-stop unconfirmed, too many requests at once (load shed), a recording's file not writable | 503 |
//! | device did not answer; a write sent whose RES or read-back was lost (`write-unverified`) | 504 |
//! | a recording's file cannot be written: the disk (or quota, or file size limit) is full | 507 |
//!
//! # Layout
//! - `documented`: the statuses every route documents; the guards' problems.
//! - `from`: each failure (core, bus, axum's rejections) mapped to its problem.
//! - this file: the problem shape, its constructors, the response.

mod documented;
mod from;

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use super::scope::{Needs, Scope};
use crate::control::ControlError;
use crate::protocol::units::UnitError;

/// Media type of every error body.
pub(crate) const PROBLEM_JSON: &str = "application/problem+json";
/// Prefix of every problem `type` (a URN: no documentation host is implied).
const TYPE_PREFIX: &str = "urn:jointd:problem:";
/// Seconds a client should wait before retrying a full request queue, or a
/// request shed because too many were being handled.
const RETRY_AFTER_BUSY_S: &str = "1";

/// The allowed range of a field that was out of it.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct AllowedRange {
    #[schema(example = -90.0)]
    pub min: f64,
    #[schema(example = 90.0)]
    pub max: f64,
    #[schema(example = "deg")]
    pub unit: String,
}

/// RFC 9457 problem details, with jointd's extension members.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({
    "type": "urn:jointd:problem:soft-limit",
    "title": "Target outside the joint's soft limits",
    "status": 422,
    "detail": "position_deg = 120 deg is outside the soft limits of joint 3 on bus0 (-90..=90 deg)",
    "field": "position_deg",
    "allowed": {"min": -90.0, "max": 90.0, "unit": "deg"}
}))]
pub struct Problem {
    /// A URN naming the kind of problem, e.g. `urn:jointd:problem:device-timeout`.
    #[serde(rename = "type")]
    pub kind: String,
    pub title: String,
    pub status: u16,
    pub detail: String,
    /// The request field at fault (JSON name), for 400/422.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The range the field must lie in, when it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub allowed: Option<AllowedRange>,
    /// What was already done before the failure (e.g. parameters written), or
    /// per-bus results of an e-stop that did not stop everything.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = partial_schema)]
    pub partial: Option<serde_json::Value>,
}

/// `partial`: a config PATCH's per-parameter outcomes, or another object
/// (per-bus e-stop results, per-bus link states).
fn partial_schema() -> utoipa::openapi::Schema {
    use utoipa::openapi::schema::{AnyOfBuilder, ObjectBuilder, Schema, Type};
    use utoipa::openapi::Ref;
    let any_of = AnyOfBuilder::new()
        .item(Ref::from_schema_name("PatchOutcomes"))
        .item(ObjectBuilder::new().schema_type(Type::Object))
        .description(Some(
            "What was already done before the failure: a config PATCH's per-parameter \
             outcomes (`PatchOutcomes`), or per-bus results of an e-stop or readiness check.",
        ))
        .build();
    Schema::AnyOf(any_of)
}

/// An error a handler returns; renders as a [`Problem`].
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    /// Boxed: errors travel in every `Result` of the API, keep them one pointer wide.
    pub problem: Box<Problem>,
}

impl ApiError {
    /// Private: a status is chosen by one of the named constructors or
    /// `From` impls below, never by a handler.
    fn new(status: StatusCode, kind: &str, title: &str, detail: impl Into<String>) -> Self {
        Self {
            problem: Box::new(Problem {
                kind: format!("{TYPE_PREFIX}{kind}"),
                title: title.to_owned(),
                status: status.as_u16(),
                detail: detail.into(),
                field: None,
                allowed: None,
                partial: None,
            }),
        }
    }

    pub fn status(&self) -> StatusCode {
        StatusCode::from_u16(self.problem.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR)
    }

    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.problem.field = Some(field.into());
        self
    }

    pub fn with_range(mut self, min: f64, max: f64, unit: &str) -> Self {
        self.problem.allowed = Some(AllowedRange {
            min,
            max,
            unit: unit.to_owned(),
        });
        self
    }

    pub fn with_partial(mut self, partial: serde_json::Value) -> Self {
        self.problem.partial = Some(partial);
        self
    }

    pub fn bad_request(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "bad-request",
            "Malformed request",
            detail,
        )
    }

    /// A well-formed value the API will not accept (422).
    pub fn invalid(field: &str, detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-value",
            "Invalid value",
            detail,
        )
        .with_field(field)
    }

    /// A value outside the range its field allows (422).
    pub fn out_of_range(field: &str, value: f64, (min, max): (f64, f64), unit: &str) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "out-of-range",
            "Value out of range",
            format!(
                "{field} = {value}{u} is out of range; allowed {min}..={max}{u}",
                u = if unit.is_empty() {
                    String::new()
                } else {
                    format!(" {unit}")
                }
            ),
        )
        .with_field(field)
        .with_range(min, max, unit)
    }

    pub fn not_found(kind: &str, detail: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, kind, "Not found", detail)
    }

    pub fn conflict(kind: &str, title: &str, detail: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, kind, title, detail)
    }

    pub fn unauthorized(detail: &str) -> Self {
        Self::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "Bearer token required",
            detail,
        )
    }

    /// A token whose scope does not reach what the route needs (403),
    /// naming the scope it needed and the token's own (by its name: never
    /// the token).
    pub fn insufficient_scope(needs: Needs, name: &str, has: Scope) -> Self {
        Self::new(
            StatusCode::FORBIDDEN,
            "insufficient-scope",
            "Token's scope too narrow",
            format!(
                "this needs a token of scope `{}`; token `{name}` is `{has}`",
                needs.name()
            ),
        )
    }

    /// A request that changes something, or a WebSocket upgrade, from a
    /// browser page of another origin (403). `what` names the header that
    /// told (`Origin`, `Sec-Fetch-Site: cross-site`).
    pub fn foreign_origin(origin: &str, what: &str) -> Self {
        Self::new(
            StatusCode::FORBIDDEN,
            "foreign-origin",
            "Request from a foreign browser origin",
            format!(
                "refused a request from {origin} ({what}): only the daemon's own origin, \
                 clients that send no Origin, and allowed_origins may change anything"
            ),
        )
    }

    /// A `Host` that names no host of this daemon (421 Misdirected Request:
    /// the daemon is not the authority for that name; a DNS-rebinding page
    /// reaches it under a name it does not own).
    pub fn misdirected(host: &str, why: &str) -> Self {
        Self::new(
            StatusCode::MISDIRECTED_REQUEST,
            "unknown-host",
            "Host not served by this daemon",
            format!("Host `{host}` is not a name of this daemon: {why}"),
        )
    }

    /// A request body over the limit (413); `limit` when known.
    pub fn payload_too_large(limit: Option<usize>) -> Self {
        let detail = match limit {
            Some(n) => format!("the request body is larger than {n} bytes (max_body_bytes)"),
            None => "the request body is larger than the limit (max_body_bytes)".to_owned(),
        };
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body-too-large",
            "Request body too large",
            detail,
        )
    }

    /// A plain request to the WebSocket endpoint (426; `Upgrade: websocket`).
    pub fn upgrade_required(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UPGRADE_REQUIRED,
            "upgrade-required",
            "WebSocket upgrade required",
            detail,
        )
    }

    /// A unit conversion's refusal, said of `field` (the control core's words).
    pub fn from_unit(field: &str, err: UnitError) -> Self {
        ControlError::from_unit(field, err).into()
    }

    pub fn method_not_allowed(method: &axum::http::Method) -> Self {
        Self::new(
            StatusCode::METHOD_NOT_ALLOWED,
            "method-not-allowed",
            "Method not allowed",
            format!("{method} is not supported on this resource"),
        )
    }

    /// A bug: a handler panicked (logged by the caller).
    pub fn internal() -> Self {
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            "Internal error",
            "the request handler failed; see the daemon log",
        )
    }

    /// `/readyz` when a bus is not up (503; `partial` names each bus's link).
    pub fn not_ready(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "not-ready",
            "Not ready",
            detail,
        )
    }

    /// Writes of one request that all went out, some without confirmation
    /// (504, like a single unverified write; `partial` lists per parameter
    /// `written`, `unverified` and `not_written`).
    pub fn writes_unverified(detail: impl Into<String>) -> Self {
        let (status, kind, title) = from::UNVERIFIED;
        Self::new(status, kind, title, detail)
    }

    /// The state file could not be written (503): nothing was changed.
    pub fn state_unwritable(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "state-unwritable",
            "State file not written",
            detail,
        )
    }

    /// A request shed because `limit` requests were already being handled
    /// (503 with Retry-After): a flood answers fast instead of queueing.
    pub fn overloaded(limit: usize) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "overloaded",
            "Too many requests at once",
            format!(
                "{limit} requests are being handled: retry later (e-stop requests are never \
                 refused for this)"
            ),
        )
    }

    /// An e-stop that could not confirm every bus stopped (503; `partial`
    /// carries each bus's result).
    pub fn estop_incomplete(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "estop-incomplete",
            "Emergency stop incomplete",
            detail,
        )
    }
}

/// The problem type of an answer, left in the response's extensions.
#[derive(Debug, Clone)]
pub(crate) struct ProblemType(pub(crate) String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let body = serde_json::to_vec(&self.problem).unwrap_or_default();
        let mut resp = (status, body).into_response();
        // For the failure log (`http::log_failures`), which sees only the response.
        resp.extensions_mut()
            .insert(ProblemType(self.problem.kind.clone()));
        let headers = resp.headers_mut();
        headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if status == StatusCode::UPGRADE_REQUIRED {
            headers.insert(header::UPGRADE, HeaderValue::from_static("websocket"));
            headers.insert(header::CONNECTION, HeaderValue::from_static("Upgrade"));
        }
        if status == StatusCode::UNAUTHORIZED {
            headers.insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if self.problem.kind.ends_with("bus-busy") || self.problem.kind.ends_with("overloaded") {
            headers.insert(
                header::RETRY_AFTER,
                HeaderValue::from_static(RETRY_AFTER_BUSY_S),
            );
        }
        resp
    }
}

pub(crate) type ApiResult<T> = Result<T, ApiError>;

pub(crate) use documented::{BODY_TOO_LARGE, DOCUMENTED_STATUSES, FORBIDDEN_ORIGIN, UNKNOWN_HOST};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::BusError;

    #[test]
    fn bus_errors_map_to_documented_statuses() {
        let cases = [
            (
                BusError::Timeout {
                    dev_id: 1,
                    what: "INFO_01".into(),
                    attempts: 2,
                    timeout_us: 1000,
                },
                504,
            ),
            (
                BusError::Down {
                    bus: "b".into(),
                    reason: "gone".into(),
                },
                503,
            ),
            (
                BusError::UnknownDevice {
                    bus: "b".into(),
                    dev_id: 9,
                },
                404,
            ),
            (BusError::WrongState("disabled".into()), 409),
            (BusError::Invalid("bad".into()), 422),
            (BusError::Preempted, 409),
            (BusError::Busy { depth: 64 }, 503),
            (BusError::Stopped, 503),
            (BusError::OwnerTimeout, 503),
            (
                BusError::Refused {
                    dev_id: 1,
                    what: "persist".into(),
                    code: 0,
                },
                409,
            ),
            (BusError::UnexpectedReply("INFO_07".into()), 502),
            (
                BusError::Unverified {
                    dev_id: 1,
                    index: 18,
                    value: 5,
                    what: "write index 18 = 5".into(),
                    reason: "no read-back".into(),
                },
                504,
            ),
            (
                BusError::VerifyMismatch {
                    dev_id: 1,
                    index: 18,
                    expected: 5,
                    found: 0,
                },
                502,
            ),
        ];
        for (err, status) in cases {
            let api = ApiError::from(err.clone());
            assert_eq!(api.problem.status, status, "{err}");
            // Every status a bus failure can get is in the OpenAPI document.
            let documented = DOCUMENTED_STATUSES
                .iter()
                .any(|(s, _)| *s == status.to_string());
            assert!(documented, "{status} of {err} is not documented");
        }
    }

    #[test]
    fn unit_range_errors_name_field_and_range() {
        let err = crate::protocol::units::angle_to_raw(300.0).unwrap_err();
        let api = ApiError::from_unit("position_deg", err);
        assert_eq!(api.problem.status, 422);
        assert_eq!(api.problem.field.as_deref(), Some("position_deg"));
        let range = api.problem.allowed.unwrap();
        assert_eq!((range.min, range.max), (-255.0, 255.0));
    }
}
