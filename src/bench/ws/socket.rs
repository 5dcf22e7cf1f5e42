//! The bench's WebSocket connections, and the names of the threads the
//! CPU report tells apart.

use tungstenite::stream::MaybeTlsStream;
use tungstenite::WebSocket;

use crate::bench::args::BenchError;

/// Names of the threads the CPU report tells apart.
pub(super) const HTTP_THREAD: &str = "jointd-http";
pub(super) const TELEOP_THREAD: &str = "bench-ws";
pub(super) const TELEMETRY_THREAD: &str = "bench-tele";

pub(super) type Socket = WebSocket<MaybeTlsStream<std::net::TcpStream>>;

pub(super) fn connect(url: &str) -> Result<Socket, BenchError> {
    let (mut ws, _) =
        tungstenite::connect(url).map_err(|e| BenchError::Setup(format!("connect {url}: {e}")))?;
    // The first message is `welcome`.
    ws.read()
        .map_err(|e| BenchError::Setup(format!("welcome: {e}")))?;
    Ok(ws)
}
