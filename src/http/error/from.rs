//! Every failure as a problem: the core's refusals, the bus's errors and
//! axum's rejections, each kind mapped to its status once, here.

use axum::extract::rejection::{JsonRejection, PathRejection, QueryRejection};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::http::StatusCode;

use super::ApiError;
use crate::bus::BusError;
use crate::control::ControlError;

/// A write sent whose confirmation was lost (the device may have taken it):
/// a gateway timeout, as the missing answer is the upstream's, with its own
/// problem type so a client never reads it as "not written".
pub(super) const UNVERIFIED: (StatusCode, &str, &str) = (
    StatusCode::GATEWAY_TIMEOUT,
    "write-unverified",
    "Write sent, confirmation lost",
);

/// Status, problem type and title of each bus failure: the one table that
/// turns what the bus reports into HTTP.
pub(super) fn bus_problem(err: &BusError) -> (StatusCode, &'static str, &'static str) {
    match err {
        BusError::Timeout { .. } => (
            StatusCode::GATEWAY_TIMEOUT,
            "device-timeout",
            "Device did not answer",
        ),
        // The write went out; only its confirmation did not come back.
        BusError::Unverified { .. } => UNVERIFIED,
        BusError::Down { .. } => (StatusCode::SERVICE_UNAVAILABLE, "bus-down", "Bus is down"),
        BusError::Refused { .. } => (StatusCode::CONFLICT, "device-refused", "Device refused"),
        // The device answered, but wrongly: the upstream failed, not the request.
        BusError::VerifyMismatch { .. } => (
            StatusCode::BAD_GATEWAY,
            "verify-mismatch",
            "Read-back differs from the value written",
        ),
        BusError::UnexpectedReply(_) => (
            StatusCode::BAD_GATEWAY,
            "unexpected-reply",
            "Unexpected reply",
        ),
        BusError::UnknownDevice { .. } => (StatusCode::NOT_FOUND, "unknown-device", "Not found"),
        BusError::WrongState(_) => (StatusCode::CONFLICT, "wrong-state", "Wrong device state"),
        BusError::Invalid(_) => (
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-value",
            "Invalid value",
        ),
        BusError::Busy { .. } => (
            StatusCode::SERVICE_UNAVAILABLE,
            "bus-busy",
            "Bus request queue full",
        ),
        BusError::Preempted => (
            StatusCode::CONFLICT,
            "preempted",
            "Preempted by an emergency stop",
        ),
        BusError::OwnerTimeout | BusError::Stopped => (
            StatusCode::SERVICE_UNAVAILABLE,
            "bus-unavailable",
            "Bus owner unavailable",
        ),
    }
}

/// The control core's refusals: each kind its status, once.
impl From<ControlError> for ApiError {
    fn from(err: ControlError) -> Self {
        match err {
            ControlError::Invalid {
                kind,
                field,
                detail,
                allowed,
            } => {
                let e = Self::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    kind.name(),
                    kind.title(),
                    detail,
                )
                .with_field(field);
                match allowed {
                    Some(a) => e.with_range(a.min, a.max, &a.unit),
                    None => e,
                }
            }
            ControlError::NotFound { kind, detail } => Self::not_found(&kind, detail),
            ControlError::Conflict {
                kind,
                title,
                detail,
                field,
            } => {
                let e = Self::conflict(&kind, &title, detail);
                match field {
                    Some(f) => e.with_field(f),
                    None => e,
                }
            }
            ControlError::StateUnwritable(detail) => Self::state_unwritable(detail),
            ControlError::Storage { full, detail } => storage_problem(full, detail),
            ControlError::Unreadable(detail) => Self::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "recording-unreadable",
                "Recording file not readable",
                detail,
            ),
            ControlError::Internal(detail) => {
                tracing::error!("internal error: {detail}");
                Self::internal()
            }
            ControlError::Bus(e) => e.into(),
        }
    }
}

/// A recording's file not written: 507 when the disk is full, else 503.
fn storage_problem(full: bool, detail: String) -> ApiError {
    if full {
        ApiError::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "storage-full",
            "No room for the recording",
            detail,
        )
    } else {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "recording-unwritable",
            "Recording file not written",
            detail,
        )
    }
}

impl From<BusError> for ApiError {
    fn from(err: BusError) -> Self {
        let (status, kind, title) = bus_problem(&err);
        Self::new(status, kind, title, err.to_string())
    }
}

impl From<JsonRejection> for ApiError {
    fn from(rej: JsonRejection) -> Self {
        // A body over DefaultBodyLimit fails while buffering; axum marks it 413.
        if rej.status() == StatusCode::PAYLOAD_TOO_LARGE {
            return ApiError::payload_too_large(None);
        }
        match rej {
            // Well-formed JSON of the wrong shape: a missing field, a string
            // where a number belongs, an unknown field.
            JsonRejection::JsonDataError(e) => ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid-body",
                "Request body does not match the schema",
                e.body_text(),
            ),
            JsonRejection::MissingJsonContentType(_) => ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Body must be application/json",
                "send the body with `Content-Type: application/json`",
            ),
            other => ApiError::bad_request(other.body_text()),
        }
    }
}

/// A plain GET to the WebSocket endpoint (no `Connection: upgrade` /
/// `Upgrade: websocket`) is told to upgrade (426); a broken handshake is
/// malformed (400).
impl From<WebSocketUpgradeRejection> for ApiError {
    fn from(rej: WebSocketUpgradeRejection) -> Self {
        match rej {
            WebSocketUpgradeRejection::InvalidConnectionHeader(_)
            | WebSocketUpgradeRejection::InvalidUpgradeHeader(_)
            | WebSocketUpgradeRejection::ConnectionNotUpgradable(_) => ApiError::upgrade_required(
                "this is the WebSocket endpoint (protocol jointd.ws.v1, docs/websocket.md): \
                 connect with a WebSocket client",
            ),
            other => ApiError::bad_request(format!("WebSocket handshake: {}", other.body_text())),
        }
    }
}

impl From<PathRejection> for ApiError {
    fn from(rej: PathRejection) -> Self {
        ApiError::bad_request(rej.body_text())
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rej: QueryRejection) -> Self {
        ApiError::bad_request(rej.body_text())
    }
}
