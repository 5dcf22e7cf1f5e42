//! The accept loop, in place of `axum::serve`, for what it lacks: a
//! connection must send its first bytes within [`FIRST_BYTES`] and a whole
//! request head within [`HEADER_READ`] (a client that dribbles or says
//! nothing is dropped, not held forever), and at most [`MAX_CONNECTIONS`]
//! are served at once (beyond, a new one is closed at once: slow clients
//! cannot take every descriptor the e-stop needs). A shutdown stops the
//! accepting and lets every connection finish its request under way.

use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::extract::Request;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto::Builder;
use hyper_util::service::TowerToHyperService;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};
use tower::ServiceExt;

/// How long a new connection may take to send its first byte.
pub const FIRST_BYTES: Duration = Duration::from_secs(5);
/// How long a request's line and headers may take to arrive, whole.
pub const HEADER_READ: Duration = Duration::from_secs(5);
/// Connections served at once (dashboards, scripts, WebSocket clients).
pub const MAX_CONNECTIONS: usize = 512;

/// Serves `app` on `listener` until `stop` resolves, then until every
/// connection finished what it was doing (the caller bounds that wait).
pub async fn serve(
    listener: TcpListener,
    app: Router,
    stop: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    // Dropped at the stop: every connection then shuts down gracefully.
    let (stopping_tx, stopping_rx) = watch::channel(false);
    let mut stop = std::pin::pin!(stop);
    loop {
        let (tcp, _) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    // Out of descriptors and the like: say so, breathe, go on.
                    tracing::warn!("accepting a connection failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut stop => break,
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::debug!("{MAX_CONNECTIONS} connections open: a new one closed");
            drop(tcp);
            continue;
        };
        if let Err(e) = tcp.set_nodelay(true) {
            tracing::warn!("TCP_NODELAY not set on a connection: {e}");
        }
        let (app, stopping) = (app.clone(), stopping_rx.clone());
        tokio::spawn(async move {
            serve_one(tcp, app, stopping).await;
            drop(slot);
        });
    }
    let _ = stopping_tx.send(true);
    // Each connection holds a slot until it ends.
    let _ = slots.acquire_many(MAX_CONNECTIONS as u32).await;
    Ok(())
}

/// One connection: its first bytes within [`FIRST_BYTES`], each request
/// head within [`HEADER_READ`], until it closes or the daemon stops.
async fn serve_one(tcp: TcpStream, app: Router, mut stopping: watch::Receiver<bool>) {
    let mut first = [0u8; 1];
    match tokio::time::timeout(FIRST_BYTES, tcp.peek(&mut first)).await {
        Ok(Ok(n)) if n > 0 => {}
        // Closed, broken, or silent for too long: nothing to serve.
        _ => return,
    }
    let service =
        TowerToHyperService::new(app.map_request(|req: Request<Incoming>| req.map(Body::new)));
    let mut builder = Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_READ);
    let conn = builder.serve_connection_with_upgrades(TokioIo::new(tcp), service);
    let mut conn = std::pin::pin!(conn);
    loop {
        tokio::select! {
            result = conn.as_mut() => {
                if let Err(e) = result {
                    tracing::trace!("a connection ended: {e}");
                }
                return;
            }
            changed = stopping.changed() => {
                if changed.is_err() || *stopping.borrow() {
                    conn.as_mut().graceful_shutdown();
                    // Wait for it to finish, then return.
                    let _ = conn.as_mut().await;
                    return;
                }
            }
        }
    }
}
