//! What the bridge declares on one open Zenoh session: one ROS node
//! (`jointd`), per bus a `joint_states` publisher and a `joint_commands`
//! subscription, and a `/diagnostics` publisher; each with its liveliness
//! token so that ROS 2 tools on rmw_zenoh list them. Joint states come from
//! the bus's frame tap (one message per poll round, as recordings);
//! commands go to [`super::command_stream`]. Opening the session, and
//! opening it again, is [`super::supervisor`]'s.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use futures_util::StreamExt;
use tokio::sync::watch;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
use tokio_stream::wrappers::BroadcastStream;
use zenoh::liveliness::LivelinessToken;

use super::command_stream;
use super::config::{NamespaceBy, Ros2Config, Ros2Mode};
use super::keys::{self, Kind, NodeIdentity};
use super::Ros2Stats;
use crate::bus::BusHandle;
use crate::bus::BusSnapshot;
use crate::control::Control;
use crate::protocol::status::{active_fault, fault_name, fsm_name_in};
use crate::record::cdr::{diagnostic_array_cdr, DiagnosticStatus};
use crate::record::joint_states::{system_ns, JointStates, Scope};

/// How long the tasks of a closing session get to finish (the command
/// stream applies its watchdog's policy) before they are aborted.
const CLOSE_GRACE: Duration = Duration::from_secs(2);

/// Everything declared on one session: the tokens, and the tasks that
/// publish and listen.
pub(super) struct Declared {
    tokens: Vec<LivelinessToken>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
    /// `true` tells the tasks the session is going.
    closing: watch::Sender<bool>,
}

impl Declared {
    /// Stops the tasks (the command stream first applies its watchdog's
    /// policy to the joints it drove: a lost link must not leave a joint
    /// heading for its limit) and undeclares the tokens.
    pub(super) async fn close(mut self) {
        let _ = self.closing.send(true);
        let deadline = tokio::time::Instant::now() + CLOSE_GRACE;
        for task in &mut self.tasks {
            if tokio::time::timeout_at(deadline, &mut *task).await.is_err() {
                task.abort();
            }
        }
        self.tokens.clear();
    }
}

impl Drop for Declared {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

/// The Zenoh configuration of the bridge's session.
pub(super) fn session_config(cfg: &Ros2Config) -> zenoh::Result<zenoh::Config> {
    let mut z = zenoh::Config::default();
    let mode = match cfg.mode {
        Ros2Mode::Client => "\"client\"",
        Ros2Mode::Peer => "\"peer\"",
    };
    z.insert_json5("mode", mode)?;
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    z.insert_json5("connect/endpoints", &list(&cfg.endpoints()))?;
    z.insert_json5("listen/endpoints", &list(&cfg.listen))?;
    // Where the router is, is said: no multicast scouting on the robot's LAN.
    z.insert_json5("scouting/multicast/enabled", "false")?;
    Ok(z)
}

/// Declares the node, its topics and their tokens on `session`, and starts
/// publishing and listening.
pub(super) async fn declare(
    session: &zenoh::Session,
    state: &Arc<Control>,
    cfg: &Ros2Config,
    stats: &Arc<Ros2Stats>,
) -> zenoh::Result<Declared> {
    let zid = session.zid();
    let session_gid: [u8; 16] = zid.to_le_bytes();
    let node = NodeIdentity {
        domain: cfg.domain(),
        session: zid.to_string(),
        node_id: 0,
        namespace: String::new(),
        name: cfg.node_name.clone(),
    };
    let (closing, closed) = watch::channel(false);
    // Built as it goes: a declaration refused half-way drops (and so stops)
    // what was started before it.
    let mut declared = Declared {
        tokens: Vec::new(),
        tasks: Vec::new(),
        closing,
    };
    let (tokens, tasks) = (&mut declared.tokens, &mut declared.tasks);
    tokens.push(
        session
            .liveliness()
            .declare_token(node.node_token())
            .await?,
    );
    let mut entity_id = 0u32;
    let mut next_entity = || {
        entity_id += 1;
        entity_id
    };
    for (name, scope) in scopes(state, cfg) {
        let ns = cfg.namespace(&name);
        let topic = keys::qualified(&ns, "joint_states");
        let (id, key) = (next_entity(), joint_state_key(&node, &topic));
        let publisher = session.declare_publisher(key.clone()).await?;
        tokens.push(announce(session, &node, id, Kind::Publisher, &topic, JOINT_STATE).await?);
        tracing::debug!(%name, %key, "ROS 2: publishing joint states");
        tasks.push(tokio::spawn(publish_joint_states(
            state.clone(),
            scope.clone(),
            cfg.joint_states_max_hz
                .map(|hz| Duration::from_secs_f64(1.0 / hz)),
            publisher,
            keys::gid(&session_gid, id),
            stats.clone(),
        )));
        let topic = keys::qualified(&ns, "joint_commands");
        let (id, key) = (next_entity(), joint_state_key(&node, &topic));
        let subscriber = session.declare_subscriber(key.clone()).await?;
        tokens.push(announce(session, &node, id, Kind::Subscription, &topic, JOINT_STATE).await?);
        tracing::debug!(%name, %key, "ROS 2: taking joint commands");
        tasks.push(tokio::spawn(command_stream::run(
            state.clone(),
            scope,
            subscriber,
            stats.clone(),
            closed.clone(),
        )));
    }
    let topic = "/diagnostics";
    let id = next_entity();
    let key = keys::topic_key(node.domain, topic, DIAGNOSTIC_ARRAY.0, DIAGNOSTIC_ARRAY.1);
    let publisher = session.declare_publisher(key).await?;
    tokens.push(announce(session, &node, id, Kind::Publisher, topic, DIAGNOSTIC_ARRAY).await?);
    let period = Duration::from_secs_f64(1.0 / cfg.diagnostics_hz);
    tasks.push(tokio::spawn(publish_diagnostics(
        state.clone(),
        publisher,
        keys::gid(&session_gid, id),
        period,
        stats.clone(),
    )));
    Ok(declared)
}

/// A message type on the network: its DDS name and its type hash.
type RosType = (&'static str, &'static str);
const JOINT_STATE: RosType = (keys::JOINT_STATE_TYPE, keys::JOINT_STATE_HASH);
const DIAGNOSTIC_ARRAY: RosType = (keys::DIAGNOSTIC_ARRAY_TYPE, keys::DIAGNOSTIC_ARRAY_HASH);

fn joint_state_key(node: &NodeIdentity, topic: &str) -> String {
    keys::topic_key(node.domain, topic, JOINT_STATE.0, JOINT_STATE.1)
}

/// The liveliness token that tells the ROS graph an endpoint exists.
async fn announce(
    session: &zenoh::Session,
    node: &NodeIdentity,
    id: u32,
    kind: Kind,
    topic: &str,
    (type_name, hash): RosType,
) -> zenoh::Result<LivelinessToken> {
    session
        .liveliness()
        .declare_token(node.endpoint_token(id, kind, topic, type_name, hash))
        .await
}

fn now_ns() -> i64 {
    i64::try_from(system_ns(SystemTime::now())).unwrap_or(i64::MAX)
}

/// What gets topics of its own: every bus, or every named hand.
fn scopes(state: &Arc<Control>, cfg: &Ros2Config) -> Vec<(String, Scope)> {
    match cfg.namespace_by {
        NamespaceBy::Bus => state
            .buses()
            .map(|b| (b.name().to_owned(), Scope::Bus(b.name().to_owned())))
            .collect(),
        NamespaceBy::Hand => state
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
            .unwrap_or_default(),
    }
}

/// The buses a scope's joints are on.
fn buses_of(state: &Arc<Control>, scope: &Scope) -> Vec<BusHandle> {
    let mut names: Vec<&str> = match scope {
        Scope::Bus(b) => vec![b.as_str()],
        Scope::Hand { joints, .. } => joints.iter().map(|(b, _)| b.as_str()).collect(),
    };
    names.dedup();
    names
        .into_iter()
        .filter_map(|n| state.bus(n).ok().cloned())
        .collect()
}

async fn publish_joint_states(
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
        BroadcastStream::new(b.shared().frame_tap.subscribe())
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
        let snaps: Vec<Arc<BusSnapshot>> = buses.iter().map(BusHandle::snapshot).collect();
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

async fn publish_diagnostics(
    state: Arc<Control>,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    period: Duration,
    stats: Arc<Ros2Stats>,
) {
    let mut tick = tokio::time::interval(period);
    let mut sequence = 0i64;
    let label = state.joint_labeler();
    loop {
        tick.tick().await;
        let mut status = Vec::new();
        for bus in state.buses() {
            let snap = bus.snapshot();
            for dev in snap.devices.values() {
                let (name, _) = label(bus.name(), dev.dev_id);
                status.push(joint_status(bus.name(), &name, dev));
            }
        }
        sequence += 1;
        let ns = now_ns();
        let cdr = diagnostic_array_cdr(u64::try_from(ns).unwrap_or(0), "", &status);
        if publisher
            .put(cdr)
            .attachment(keys::attachment(sequence, ns, &gid))
            .await
            .is_ok()
        {
            stats.diagnostics.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// One joint as `diagnostic_msgs/DiagnosticStatus`: OK running or ready,
/// WARN disabled by something, ERROR faulted, STALE offline.
fn joint_status(bus: &str, name: &str, dev: &crate::bus::handle::DeviceState) -> DiagnosticStatus {
    let info = dev.info01.as_ref().map(|(i, _)| *i);
    let fault = info.map_or(0, |i| active_fault(i.err_code));
    let (level, message) = if !dev.online {
        (3, "offline".to_string())
    } else if fault != 0 {
        (2, format!("fault: {}", fault_name(fault)))
    } else if let Some(reason) = dev.disabled_reason {
        (1, format!("disabled ({})", reason.name()))
    } else {
        (
            0,
            info.map_or("no status yet".into(), |i| {
                fsm_name_in(i.fsm, dev.firmware.map(|f| f.revision)).to_string()
            }),
        )
    };
    let mut values = vec![
        ("bus".to_string(), bus.to_string()),
        ("id".to_string(), dev.dev_id.to_string()),
        ("online".to_string(), dev.online.to_string()),
    ];
    if let Some(i) = info {
        values.push((
            "state".into(),
            fsm_name_in(i.fsm, dev.firmware.map(|f| f.revision)).into(),
        ));
        values.push(("fault".into(), fault_name(fault).into()));
        values.push(("temperature_c".into(), format!("{:.1}", i.temp_c())));
        values.push(("voltage_v".into(), format!("{:.2}", i.vbus_v())));
    }
    DiagnosticStatus {
        level,
        name: format!("jointd: {name}"),
        message,
        hardware_id: format!("{bus}/{}", dev.dev_id),
        values,
    }
}
