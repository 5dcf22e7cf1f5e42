//! The live view in Foxglove (`--foxglove ADDR`, `foxglove =`): the
//! Foxglove app connects to the daemon and plots the joints as they move,
//! with the channels, schemas and message bytes of an MCAP recording, so
//! one Foxglove layout works live and on a file (docs/foxglove.md).
//!
//! Why Foxglove's SDK (the `foxglove` crate, its WebSocket server only):
//! it is the protocol's reference server, kept in step with the app by the
//! people who make the app; writing the protocol a second time here would
//! be one more thing to keep in step. What goes on the channels is ours:
//! the recorder's table of channels and its encoder of a bus's taps
//! ([`crate::record::channels`], [`crate::record::tap`]).
//!
//! Off by default; on, loopback unless an address says otherwise (the
//! protocol has no authentication). Read only: the server offers no
//! capability a client could act through. A slow or stalled client slows
//! nothing but itself: the feed never waits for a client, the bus owner
//! never waits for the feed.
//!
//! # Layout
//! One-way: each file imports only from files above it.
//! - `addr`: the flag's value; a bare port is loopback. Pure.
//! - `server`: the SDK's server with every bus's channels, a bounded queue
//!   per client, a listener counting clients.
//! - `feed`: the thread that drains the buses' taps into the channels.
//! - this file: [`LiveView`], bound, fed, stopped; [`LiveError`].

mod addr;
mod feed;
mod server;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use thiserror::Error;

use crate::control::foxglove_stats::FoxgloveStats;
use crate::control::Control;
use crate::record::tap::{BusTap, Taps};
use feed::Feed;
use server::LiveServer;

pub use addr::parse_addr;

/// How long a stop waits for the clients' connections to close.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(1);

/// Why the live view could not start.
#[derive(Debug, Error)]
pub enum LiveError {
    #[error(
        "cannot listen for Foxglove on {addr} (is another jointd or Foxglove server on it?); \
         choose another address with --foxglove, e.g. --foxglove 8766 \
         (or `foxglove` in the config file): {source}"
    )]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("Foxglove server: {0}")]
    Sdk(String),
    #[error("Foxglove live view: cannot start its thread: {0}")]
    Thread(std::io::Error),
}

/// The live view: its server, and once the buses run, its feed.
pub struct LiveView {
    server: LiveServer,
    feed: Option<Feed>,
    stats: Arc<FoxgloveStats>,
}

/// Where it listens.
impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.server.addr())
            .field("fed", &self.feed.is_some())
            .finish_non_exhaustive()
    }
}

impl LiveView {
    /// Listens on `addr` with the channels of `buses` advertised (before
    /// any bus opens: a taken address stops the daemon there).
    pub async fn bind(
        addr: SocketAddr,
        buses: &[String],
        stats: Arc<FoxgloveStats>,
    ) -> Result<Self, LiveError> {
        let server = LiveServer::bind(addr, buses, stats.clone()).await?;
        Ok(Self {
            server,
            feed: None,
            stats,
        })
    }

    /// Where it listens (the port the system chose, when asked for 0).
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// Feeds it from every bus of `control` (once; again does nothing).
    pub fn feed(&mut self, control: &Arc<Control>) -> Result<(), LiveError> {
        if self.feed.is_some() {
            return Ok(());
        }
        let labeler = control.joint_labeler();
        let buses: Vec<(BusTap, server::BusChannels)> = control
            .readers()
            .filter_map(|bus| {
                let channels = self.server.channels(bus.name())?;
                let taps = Taps {
                    snapshots: bus.watch(),
                    frames: bus.frame_tap(),
                    setpoints: bus.setpoint_tap(),
                    events: bus.events(),
                };
                Some((BusTap::new(bus.name(), taps, labeler.clone()), channels))
            })
            .collect();
        let feed = Feed::spawn(buses, self.stats.clone()).map_err(LiveError::Thread)?;
        self.feed = Some(feed);
        Ok(())
    }

    /// Stops the feed, then the server: each client gets its connection
    /// closed (waited for at most [`CLOSE_TIMEOUT`]).
    pub async fn stop(self) {
        if let Some(feed) = self.feed {
            // At most one drain to wait for: off the async workers.
            let _ = tokio::task::spawn_blocking(move || feed.stop()).await;
        }
        let closing = self.server.stop();
        if tokio::time::timeout(CLOSE_TIMEOUT, closing.wait())
            .await
            .is_err()
        {
            tracing::debug!("Foxglove clients not closed within {CLOSE_TIMEOUT:?}: dropped");
        }
    }
}
