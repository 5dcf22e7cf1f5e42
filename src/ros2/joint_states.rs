//! `joint_states` per namespace (a bus, or a hand): one message per poll
//! round of the namespace's joints, at most `joint_states_max_hz`, each
//! with the sequence and source stamp rmw_zenoh attaches.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use futures_util::StreamExt;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
use tokio_stream::wrappers::BroadcastStream;

use super::config::{NamespaceBy, Ros2Config};
use super::keys;
use crate::bus::BusSnapshot;
use crate::control::bus_reader::BusReader;
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;
use crate::record::joint_states::{system_ns, JointStates, Scope};

fn now_ns() -> i64 {
    i64::try_from(system_ns(SystemTime::now())).unwrap_or(i64::MAX)
}

/// What gets topics of its own: every bus, or every named hand.
pub(super) fn scopes(state: &Arc<Control>, cfg: &Ros2Config) -> Vec<(String, Scope)> {
    match cfg.namespace_by {
        NamespaceBy::Bus => state
            .readers()
            .map(|b| (b.name().to_owned(), Scope::Bus(b.name().to_owned())))
            .collect(),
        NamespaceBy::Hand => hand_scopes(state),
    }
}

/// Every named hand, each with its joints.
pub(super) fn hand_scopes(state: &Control) -> Vec<(String, Scope)> {
    state
        .hands()
        .map(|store| {
            store
                .hands()
                .iter()
                .map(|h| {
                    let joints = h.joints.iter().map(|j| (j.bus.clone(), j.id)).collect();
                    let scope = Scope::Hand {
                        name: h.name.clone(),
                        joints,
                    };
                    (h.name.clone(), scope)
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The buses a scope's joints are on.
fn buses_of(state: &Arc<Control>, scope: &Scope) -> Vec<BusReader> {
    let mut names: Vec<&str> = match scope {
        Scope::Bus(b) => vec![b.as_str()],
        Scope::Hand { joints, .. } => joints.iter().map(|(b, _)| b.as_str()).collect(),
    };
    names.dedup();
    names
        .into_iter()
        .filter_map(|n| state.reader(n).ok())
        .collect()
}

pub(super) async fn publish_joint_states(
    state: Arc<Control>,
    scope: Scope,
    min_gap: Option<Duration>,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    stats: Arc<Ros2Stats>,
) {
    let buses = buses_of(&state, &scope);
    // Every bus's frames in one stream, each with its bus's name.
    let mut frames = futures_util::stream::select_all(buses.iter().map(|b| {
        let name = b.name().to_owned();
        BroadcastStream::new(b.frame_tap())
            .map(move |f| (name.clone(), f))
            .boxed()
    }));
    let mut states = JointStates::of(scope, state.joint_labeler());
    let mut sequence = 0i64;
    let mut last_put: Option<Instant> = None;
    while let Some((bus, frame)) = frames.next().await {
        let frame = match frame {
            Ok(f) => f,
            Err(BroadcastStreamRecvError::Lagged(n)) => {
                stats.frames_lost.fetch_add(n, Ordering::Relaxed);
                continue;
            }
        };
        states.on_frame(&bus, &frame);
        let snaps: Vec<Arc<BusSnapshot>> = buses.iter().map(BusReader::snapshot).collect();
        let views: Vec<&BusSnapshot> = snaps.iter().map(Arc::as_ref).collect();
        let Some(msg) = states.next(&views) else {
            continue;
        };
        // Over the cap: this round is skipped (the next carries newer data).
        let now = Instant::now();
        if min_gap.is_some_and(|gap| last_put.is_some_and(|t| now < t + gap)) {
            continue;
        }
        last_put = Some(now);
        sequence += 1;
        let attachment = keys::attachment(sequence, now_ns(), &gid);
        match publisher.put(msg.to_cdr()).attachment(attachment).await {
            Ok(()) => {
                stats.joint_states.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                if stats.publish_errors.fetch_add(1, Ordering::Relaxed) == 0 {
                    tracing::warn!(%bus, error = %e, "ROS 2: a joint state could not be published (said once)");
                }
            }
        }
    }
}
