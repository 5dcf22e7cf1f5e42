//! The WebSocket endpoint `/api/v1/ws` (protocol `jointd.ws.v1`,
//! docs/websocket.md): telemetry streams for dashboards and high-rate
//! setpoints for teleoperation, on the same bus handles as the REST API.
//!
//! # Layout
//! - `replies`: what the daemon sends (and the error codes), the telemetry fields.
//! - [`messages`]: the client's messages, parsed strictly.
//! - `subscribe`: a `subscribe` checked into a subscription.
//! - `ticker`: when a subscription's telemetry goes out (a grid shared by the connections).
//! - [`session`]: one connection's reader: apply messages, run its watchdog
//!   ([`crate::control::watchdog`]) and its streams ([`crate::control::streams`]).
//! - `outbox`: a session's replies to its writer: bounded, a stream's end held.
//! - [`writer`]: one connection's writer: telemetry, events, acks; bounded.
//! - [`setpoints`]: validate a batch whole, then store it.
//! - [`grasp`]: start, release and stop grasps; tell the starter when one ended.
//! - `actions`: enable, disable and the e-stop, each in a task of its own.
//! - `welcome`: the first message, the buses and the limits.
//! - [`telemetry`]: snapshot → joint fields in physical units.

mod actions;
pub(crate) mod grasp;
pub(crate) mod messages;
mod outbox;
mod replies;
pub mod session;
pub(crate) mod setpoints;
mod subscribe;
pub(crate) mod telemetry;
mod ticker;
mod welcome;
pub(crate) mod writer;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::{Query, State, WebSocketUpgrade};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Extension;
use axum::Router;
use futures_util::StreamExt;

use crate::http::error::ApiError;
use crate::http::paths::WS_PATH;
use crate::http::state::AppState;
use crate::http::tokens::Caller;
/// Largest client message accepted (a full batch is well under this).
const MAX_MESSAGE_BYTES: usize = 256 * 1024;
/// How much of the read buffer one read of the socket offers. The codec
/// zeroes that much before every read (128 KiB by default): at the 1 kHz
/// a teleop client sends, that is 128 MB/s of memset for messages of a
/// few hundred bytes. A longer message is still read whole: the codec
/// reserves its full length once its header is in.
const READ_CHUNK_BYTES: usize = 8 * 1024;

pub fn router() -> Router<AppState> {
    Router::new().route(WS_PATH, get(upgrade))
}

/// Longest client name (`?client=`), characters.
const MAX_CLIENT_NAME: usize = 64;

/// The upgrade's query: `token` is read by the auth layer; `client` names
/// the program (the dashboard shows it beside the joints it streams to).
#[derive(Debug, serde::Deserialize)]
struct UpgradeQuery {
    client: Option<String>,
}

/// A client's name as given, or why it is refused.
fn client_name(query: UpgradeQuery) -> Result<Option<String>, ApiError> {
    let Some(name) = query.client else {
        return Ok(None);
    };
    // Printable ASCII only: a name shown to a person beside the joints it
    // drives must not hide characters (zero-width, bidi overrides).
    let chars = name.chars().count();
    if chars == 0
        || chars > MAX_CLIENT_NAME
        || !name.chars().all(|c| c == ' ' || c.is_ascii_graphic())
    {
        return Err(ApiError::bad_request(format!(
            "`client` must be 1 to {MAX_CLIENT_NAME} printable ASCII characters (it names the program in the dashboard)"
        )));
    }
    Ok(Some(name))
}

async fn upgrade(
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
    query: Result<Query<UpgradeQuery>, axum::extract::rejection::QueryRejection>,
    caller: Option<Extension<Caller>>,
    State(state): State<AppState>,
) -> Response {
    // The auth layer names every caller; were it ever missing, the
    // connection may look and stop, nothing more.
    let caller = caller.map_or_else(Caller::unknown, |Extension(c)| c);
    let ws = match ws {
        Ok(ws) => ws,
        Err(rej) => return ApiError::from(rej).into_response(),
    };
    let name = match query
        .map_err(|e| ApiError::bad_request(format!("the WebSocket URL's query: {e}")))
        .and_then(|Query(q)| client_name(q))
    {
        Ok(name) => name,
        Err(e) => return e.into_response(),
    };
    ws.max_message_size(MAX_MESSAGE_BYTES)
        .read_buffer_size(READ_CHUNK_BYTES)
        .on_upgrade(move |socket| async move {
            let (sink, stream) = socket.split();
            session::run_as(state, caller, name, sink, stream).await;
        })
}
