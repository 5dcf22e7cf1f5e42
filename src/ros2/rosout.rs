//! `/rosout` (`rcl_interfaces/msg/Log`): the bridge's warnings about
//! commands and trajectories it dropped, as ROS 2 nodes log theirs, so
//! that `ros2 topic echo /rosout` (and rqt_console) show why a controller's
//! commands have no effect. Each cause at most once per
//! [`super::throttle::EVERY`]; the drops are counted in `GET /api/v1/ros2`
//! whether said or not.

use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime};

use tokio::sync::mpsc;

use super::keys;
use super::throttle::Throttle;
use crate::record::joint_states::system_ns;
use crate::rosmsg::bridge::{Log, LOG_WARN};

/// Warnings waiting for the publisher; more are dropped (they are counted).
const QUEUE: usize = 16;

/// A handle to say warnings on `/rosout`; cloned into every task.
#[derive(Clone)]
pub(super) struct Rosout {
    tx: mpsc::Sender<Log>,
    throttle: Arc<Mutex<Throttle>>,
    node: String,
}

impl Rosout {
    /// The handle, and the task that publishes what it is given.
    pub(super) fn new(
        node: &str,
        publisher: zenoh::pubsub::Publisher<'static>,
        gid: [u8; 16],
    ) -> (Self, impl std::future::Future<Output = ()>) {
        let (tx, rx) = mpsc::channel(QUEUE);
        let handle = Self {
            tx,
            throttle: Arc::default(),
            node: node.to_owned(),
        };
        (handle, publish(rx, publisher, gid))
    }

    /// Says `msg` at level WARN, unless `cause` was said less than five
    /// seconds ago.
    pub(super) fn warn(&self, cause: &str, msg: String) {
        let allowed = self
            .throttle
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .allow(cause, Instant::now());
        if allowed {
            let log = Log {
                stamp_ns: system_ns(SystemTime::now()),
                level: LOG_WARN,
                name: self.node.clone(),
                msg,
                ..Log::default()
            };
            // A full queue: the publisher is behind; the drop is counted anyway.
            let _ = self.tx.try_send(log);
        }
    }
}

async fn publish(
    mut rx: mpsc::Receiver<Log>,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
) {
    let mut sequence = 0i64;
    while let Some(log) = rx.recv().await {
        sequence += 1;
        let at = i64::try_from(log.stamp_ns).unwrap_or(i64::MAX);
        let put = publisher
            .put(log.to_cdr())
            .attachment(keys::attachment(sequence, at, &gid));
        if let Err(e) = put.await {
            tracing::debug!(error = %e, "ROS 2: a /rosout message could not be published");
        }
    }
}
