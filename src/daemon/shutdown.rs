//! Serving until SIGINT or SIGTERM, then stopping in order: the requests
//! under way (bounded), the WebSocket sessions, every joint disabled and
//! every port closed, the recordings' summaries written.

use std::time::Duration;

use tokio::net::TcpListener;
use tokio::signal::unix::{signal, SignalKind};

use super::error::DaemonError;
use crate::foxglove::LiveView;
use crate::http::{app, AppState};

/// How long shutdown waits for each bus to disable its joints and close.
const BUS_STOP_TIMEOUT: Duration = Duration::from_secs(5);

/// Serves the API until SIGINT or SIGTERM, then for at most
/// [`HTTP_DRAIN_TIMEOUT`] while the requests under way finish: a flood of
/// requests (or one that waits on a slow bus) cannot hold the shutdown,
/// and with it the joints' disable.
pub(super) async fn serve(listener: TcpListener, state: &AppState) -> Result<(), DaemonError> {
    let (signalled_tx, mut signalled) = tokio::sync::watch::channel(false);
    let ws_state = state.clone();
    let a_signal = shutdown_signal();
    let stopping = async move {
        a_signal.await;
        // WebSocket sessions outlive the HTTP connections they upgraded:
        // tell them, so each client gets a close frame (1001).
        ws_state.ws().shut_down();
        let _ = signalled_tx.send(true);
    };
    let serving = crate::http::serve::serve(listener, app(state.clone()), stopping);
    let drained = async {
        if signalled.wait_for(|s| *s).await.is_err() {
            return std::future::pending().await;
        }
        tokio::time::sleep(HTTP_DRAIN_TIMEOUT).await;
    };
    tokio::select! {
        served = serving => served.map_err(|e| DaemonError::Io {
            what: "HTTP server".into(),
            source: e,
        }),
        () = drained => {
            tracing::warn!("requests still open {HTTP_DRAIN_TIMEOUT:?} after the signal: \
                stopping without them");
            Ok(())
        }
    }
}

/// How long shutdown lets the requests under way finish.
const HTTP_DRAIN_TIMEOUT: Duration = Duration::from_secs(2);
/// How long shutdown waits for the recordings to write their summaries.
const RECORDINGS_CLOSE_TIMEOUT: Duration = Duration::from_secs(3);

/// Stops what the daemon started, in order, once it no longer serves: the
/// WebSocket sessions are closed, then the joints (a recording still
/// closing must not hold them), the recordings and the live view; the ROS
/// graph is left once the buses are stopped.
pub(super) async fn stop_all(
    state: &AppState,
    threads: Vec<crate::bus::BusThread>,
    live: Option<LiveView>,
    bridge: Option<impl std::fmt::Debug>,
) {
    wait_for_ws_close(state).await;
    stop_buses(threads).await;
    stop_recordings(state).await;
    if let Some(live) = live {
        live.stop().await;
    }
    if let Some(bridge) = bridge {
        tracing::debug!(?bridge, "ROS 2 bridge closing");
    }
}

/// Closes the recordings still running (bounded: a slow disk cannot hold
/// the exit); one not closed in time keeps its chunks, not its summary.
async fn stop_recordings(state: &AppState) {
    let closing = crate::control::recordings::stop_all(state.control());
    if tokio::time::timeout(RECORDINGS_CLOSE_TIMEOUT, closing)
        .await
        .is_err()
    {
        tracing::error!(
            "recordings not closed within {RECORDINGS_CLOSE_TIMEOUT:?}: left as they are"
        );
    }
}

/// How long shutdown waits for WebSocket sessions to send their close frames.
const WS_CLOSE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// Waits (bounded) until every WebSocket session has closed.
async fn wait_for_ws_close(state: &AppState) {
    let deadline = tokio::time::Instant::now() + WS_CLOSE_TIMEOUT;
    while state
        .ws()
        .connections
        .load(std::sync::atomic::Ordering::Relaxed)
        > 0
        && tokio::time::Instant::now() < deadline
    {
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
}

/// Disables every joint and closes each port (the owner does both on
/// stop), every bus at once.
async fn stop_buses(threads: Vec<crate::bus::BusThread>) {
    let stops = threads.into_iter().map(|thread| async move {
        let stopping = tokio::task::spawn_blocking(move || thread.stop());
        if tokio::time::timeout(BUS_STOP_TIMEOUT, stopping)
            .await
            .is_err()
        {
            tracing::error!("a bus did not stop within {BUS_STOP_TIMEOUT:?}");
        }
    });
    futures_util::future::join_all(stops).await;
}

/// Resolves on the first SIGINT or SIGTERM.
/// Installs the SIGINT and SIGTERM handlers now, before the API answers
/// anyone (a signal before them would end the process unannounced, the
/// joints' disable unsent); the future resolves at the first signal.
fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    let handlers = (
        signal(SignalKind::interrupt()),
        signal(SignalKind::terminate()),
    );
    async move {
        let (Ok(mut int), Ok(mut term)) = handlers else {
            tracing::error!("cannot install signal handlers; stop with SIGKILL");
            return std::future::pending().await;
        };
        tokio::select! {
            _ = int.recv() => tracing::info!("SIGINT: shutting down"),
            _ = term.recv() => tracing::info!("SIGTERM: shutting down"),
        }
    }
}
