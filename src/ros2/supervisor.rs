//! The bridge's one background task: opens the Zenoh session, declares the
//! bridge on it ([`super::bridge`]), watches that the router stays
//! reachable, and when it is not (or was never), closes what there was and
//! tries again after [`super::link`]'s wait. The daemon never waits on it:
//! buses and HTTP serve whether or not a router is there.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use super::bridge::{self, Declared};
use super::config::{Ros2Config, Ros2Mode};
use super::link::{Link, Say};
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;

/// How often an open session is checked for its router.
const CHECK_EVERY: Duration = Duration::from_millis(250);

/// Runs until aborted (dropping the [`super::Bridge`]).
pub(super) async fn supervise(
    state: Arc<Control>,
    cfg: Ros2Config,
    zenoh_cfg: zenoh::Config,
    stats: Arc<Ros2Stats>,
) {
    let mut link = Link::default();
    loop {
        match open(&state, &cfg, &zenoh_cfg, &stats).await {
            Ok((session, declared)) => {
                // Said before it is shown: whoever sees the change through
                // the API finds its line in the log.
                say(link.connected(), &cfg, "");
                stats.connects.fetch_add(1, Ordering::Relaxed);
                stats.connected.store(true, Ordering::Relaxed);
                until_lost(&session, cfg.mode).await;
                say(link.lost(), &cfg, "");
                set_error(&stats, "the router went away".into());
                stats.connected.store(false, Ordering::Relaxed);
                declared.close().await;
                // Dropped either way: an error closing it changes nothing.
                let _ = session.close().await;
            }
            Err(e) => {
                let why = e.to_string();
                let (what, wait) = link.failed();
                say(what, &cfg, &why);
                set_error(&stats, why);
                tokio::time::sleep(wait).await;
            }
        }
    }
}

/// A session with everything declared on it.
async fn open(
    state: &Arc<Control>,
    cfg: &Ros2Config,
    zenoh_cfg: &zenoh::Config,
    stats: &Arc<Ros2Stats>,
) -> zenoh::Result<(zenoh::Session, Declared)> {
    let session = zenoh::open(zenoh_cfg.clone()).await?;
    match bridge::declare(&session, state, cfg, stats).await {
        Ok(declared) => Ok((session, declared)),
        Err(e) => {
            let _ = session.close().await;
            Err(e)
        }
    }
}

/// Returns when a client session has no router any more. A peer's session
/// is never lost this way: peers come and go, it stays open for them.
async fn until_lost(session: &zenoh::Session, mode: Ros2Mode) {
    loop {
        tokio::time::sleep(CHECK_EVERY).await;
        if mode == Ros2Mode::Client && session.info().routers_zid().await.next().is_none() {
            return;
        }
    }
}

fn set_error(stats: &Ros2Stats, why: String) {
    *stats.last_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(why);
}

/// Logs a change of the link (`error`: why a connect failed). Called before
/// the change is published in `stats`.
fn say(what: Say, cfg: &Ros2Config, error: &str) {
    let endpoints = cfg.endpoints();
    match what {
        Say::Nothing => {}
        Say::Unreachable => tracing::warn!(?endpoints, %error,
            "ROS 2 bridge: no Zenoh router reachable; retrying in the background (said once until it connects; GET /api/v1/ros2 has the latest error)"),
        Say::Connected => tracing::info!(?endpoints, mode = ?cfg.mode, domain = cfg.domain(),
            node = %cfg.node_name, "ROS 2 bridge connected (rmw_zenoh key expressions)"),
        Say::Lost => tracing::warn!(?endpoints,
            "ROS 2 bridge: the Zenoh router went away; retrying in the background (said once until it connects again)"),
    }
}
