//! `jointd [run]`: config file and flags → buses (serial or an in-process
//! simulator: on a pty, or behind a USB adapter model on an in-memory line)
//! → the HTTP API (and the live Foxglove view, when asked) → on
//! SIGINT/SIGTERM stop accepting, let the requests under way finish (for a
//! bounded time), disable every joint, close the ports, close the
//! recordings and the live view, exit 0.
//!
//! # Layout
//! One-way: each file imports only from files above it.
//! - `error`: [`DaemonError`]: what keeps the daemon from starting, with the way out.
//! - `args`: the flags ([`RunArgs`]) and the config file's shape ([`FileConfig`]).
//! - `plan`: flags and file checked into the daemon's [`Plan`].
//! - `start`: the simulator of `--sim`, one owner per bus, the live Foxglove view's server.
//! - `tokens`: the scoped tokens of `[[tokens]]`, each secret from a file or the environment.
//! - `shutdown`: serving until a signal, then draining, disabling, closing.
//! - this file: the order of it all ([`run`]).

mod args;
mod error;
mod plan;
mod shutdown;
mod start;
pub mod tokens;

use std::sync::Arc;

use tokio::net::TcpListener;

use crate::control::Control;
use crate::http::tokens::Tokens;
use crate::http::AppState;
use error::listen_error;
use shutdown::{serve, stop_all};
use start::{bind_live, raise_open_files_limit, start_all, Started};

pub use args::{FileConfig, JointName, RunArgs, DEFAULT_LISTEN, SIM_BUS_NAME};
pub use error::DaemonError;
pub use plan::{plan, Plan};

/// Runs the daemon until SIGINT or SIGTERM.
pub async fn run(args: RunArgs) -> Result<(), DaemonError> {
    let plan = plan(&args)?;
    raise_open_files_limit();
    // Bound before any bus opens: a second daemon on a taken address stops
    // there, without touching a port (nor sending a shutdown's disable).
    let listener = TcpListener::bind(plan.listen)
        .await
        .map_err(|e| listen_error(plan.listen, e))?;
    let mut live = bind_live(&plan).await?;
    let Started {
        sim,
        handles,
        threads,
        managed,
    } = start_all(plan.buses, plan.sim)?;
    let addr = listener.local_addr().map_err(|e| DaemonError::Io {
        what: "listener address".into(),
        source: e,
    })?;
    // First line on stdout: scripts and tests read the port from it.
    println!("listening on http://{addr}");
    let tokens = Tokens::single(plan.token).and(plan.tokens);
    tracing::info!(%addr, tokens = ?tokens.names(), "serving the API (tokens by name and scope; none: the API is open)");
    // One core, handed to HTTP and ROS 2 alike.
    let control = Arc::new(Control::new(handles, plan.limits));
    let mut control_options = plan.control;
    control_options.managed = managed;
    let ros2_stats = control_options.ros2.clone();
    // A fresh core and a fresh state have no options yet: neither call
    // can be refused.
    let _ = control.set_options(control_options);
    if let Some(live) = live.as_mut() {
        live.feed(&control)?;
    }
    let state = AppState::with_tokens(control.clone(), tokens);
    let mut http_options = plan.http;
    http_options.policy.listen = Some(addr);
    let _ = state.set_options(http_options);
    // The bridge lives until the daemon stops (dropped below: the ROS
    // graph sees its tokens go).
    let bridge = match (plan.ros2, ros2_stats) {
        (Some(cfg), Some(stats)) => Some(
            crate::ros2::start(control.clone(), cfg, stats)
                .map_err(|e| DaemonError::Policy(e.to_string()))?,
        ),
        _ => None,
    };
    serve(listener, &state).await?;
    stop_all(&state, threads, live, bridge).await;
    drop(sim);
    tracing::info!("stopped");
    Ok(())
}
