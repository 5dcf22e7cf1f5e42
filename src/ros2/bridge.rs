//! The bridge itself: one Zenoh session, one ROS node (`jointd`), per bus
//! a `joint_states` publisher and a `joint_commands` subscription, and a
//! `/diagnostics` publisher; each with its liveliness token so that ROS 2
//! tools on rmw_zenoh list them. Joint states come from the bus's frame tap
//! (one message per poll round, as recordings); commands go through
//! [`super::commands`].

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use futures_util::StreamExt;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
use tokio_stream::wrappers::BroadcastStream;
use zenoh::liveliness::LivelinessToken;

use super::commands;
use super::config::{NamespaceBy, Ros2Config, Ros2Mode};
use super::keys::{self, Kind, NodeIdentity};
use super::Ros2Stats;
use crate::bus::authority::Epoch;
use crate::bus::BusHandle;
use crate::bus::BusSnapshot;
use crate::bus::Setpoint;
use crate::control::streams::Streams;
use crate::control::watchdog::{fire_policy, Watchdog};
use crate::control::Control;
use crate::control::JointRef;
use crate::protocol::status::{active_fault, fault_name, fsm_name_in};
use crate::record::cdr::{diagnostic_array_cdr, DiagnosticStatus, JointState};
use crate::record::joint_states::{system_ns, JointStates, Scope};

/// What keeps the bridge alive: dropping it undeclares everything.
pub struct Bridge {
    _session: zenoh::Session,
    _tokens: Vec<LivelinessToken>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl Drop for Bridge {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge")
            .field("tasks", &self.tasks.len())
            .finish_non_exhaustive()
    }
}

fn session_config(cfg: &Ros2Config) -> zenoh::Result<zenoh::Config> {
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

/// Opens the session and starts publishing and listening.
pub(super) async fn start(
    state: Arc<Control>,
    cfg: Ros2Config,
    stats: Arc<Ros2Stats>,
) -> zenoh::Result<Bridge> {
    let session = zenoh::open(session_config(&cfg)?).await?;
    let zid = session.zid();
    let session_gid: [u8; 16] = zid.to_le_bytes();
    let node = NodeIdentity {
        domain: cfg.domain(),
        session: zid.to_string(),
        node_id: 0,
        namespace: String::new(),
        name: cfg.node_name.clone(),
    };
    let mut tokens = vec![
        session
            .liveliness()
            .declare_token(node.node_token())
            .await?,
    ];
    let mut tasks = Vec::new();
    let mut entity_id = 0u32;
    let mut next_entity = || {
        entity_id += 1;
        entity_id
    };
    for (name, scope) in scopes(&state, &cfg) {
        let ns = cfg.namespace(&name);
        let topic = keys::qualified(&ns, "joint_states");
        let (id, key) = (next_entity(), joint_state_key(&node, &topic));
        let publisher = session.declare_publisher(key.clone()).await?;
        tokens.push(announce(&session, &node, id, Kind::Publisher, &topic, JOINT_STATE).await?);
        tracing::info!(%name, %key, "ROS 2: publishing joint states");
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
        tokens.push(announce(&session, &node, id, Kind::Subscription, &topic, JOINT_STATE).await?);
        tracing::info!(%name, %key, "ROS 2: taking joint commands");
        tasks.push(tokio::spawn(take_commands(
            state.clone(),
            scope,
            subscriber,
            stats.clone(),
        )));
    }
    let topic = "/diagnostics";
    let id = next_entity();
    let key = keys::topic_key(node.domain, topic, DIAGNOSTIC_ARRAY.0, DIAGNOSTIC_ARRAY.1);
    let publisher = session.declare_publisher(key).await?;
    tokens.push(
        announce(
            &session,
            &node,
            id,
            Kind::Publisher,
            topic,
            DIAGNOSTIC_ARRAY,
        )
        .await?,
    );
    let period = Duration::from_secs_f64(1.0 / cfg.diagnostics_hz);
    tasks.push(tokio::spawn(publish_diagnostics(
        state.clone(),
        publisher,
        keys::gid(&session_gid, id),
        period,
        stats.clone(),
    )));
    tracing::info!(zid = %zid, domain = node.domain, mode = ?cfg.mode, endpoints = ?cfg.endpoints(),
        node = %cfg.node_name, "ROS 2 bridge up (rmw_zenoh key expressions)");
    Ok(Bridge {
        _session: session,
        _tokens: tokens,
        tasks,
    })
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

/// Commands in; the teleoperation watchdog of `[watchdog]` over them.
async fn take_commands(
    state: Arc<Control>,
    scope: Scope,
    subscriber: zenoh::pubsub::Subscriber<
        zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>,
    >,
    stats: Arc<Ros2Stats>,
) {
    // The one teleop watchdog, as a WebSocket client gets it by default.
    let default = state.watchdog_default();
    let mut watchdog = Watchdog::default();
    watchdog.arm(
        Duration::from_millis(default.hold_timeout_ms),
        default.policy,
        tokio::time::Instant::now(),
    );
    let mut said_bad = false;
    let mut streams = Streams::default();
    let mut last_command: Option<tokio::time::Instant> = None;
    loop {
        let sample = match watchdog.deadline() {
            Some(d) => match tokio::time::timeout_at(d, subscriber.recv_async()).await {
                Ok(s) => s,
                Err(_) => {
                    if let Some((policy, joints)) = watchdog.fire() {
                        tracing::warn!(?joints, ?policy, "ROS 2: joint commands stopped: watchdog");
                        fire_policy(&state, policy, &joints).await;
                        stats.watchdog_fired.fetch_add(1, Ordering::Relaxed);
                    }
                    continue;
                }
            },
            None => subscriber.recv_async().await,
        };
        let Ok(sample) = sample else { return };
        let bytes = sample.payload().to_bytes();
        let now = tokio::time::Instant::now();
        // A ROS 2 topic has no way to ask for a new stream: commands after
        // a pause begin one; a controller streaming on through an e-stop and
        // a later enable does not drive the joints again until it pauses.
        let restart = last_command.map_or(true, |at| now.duration_since(at) >= STREAM_RESTART_GAP);
        last_command = Some(now);
        let outcome = JointState::from_cdr(&bytes)
            .map_err(|e| format!("not a sensor_msgs/msg/JointState in CDR: {e}"))
            .and_then(|cmd| commands::setpoints(&state, &scope, &cmd))
            .and_then(|per_bus| streamed(&state, &mut streams, per_bus, restart));
        match outcome {
            Ok(per_bus) => {
                let mut fed = Vec::new();
                for (bus, targets) in per_bus {
                    fed.extend(targets.iter().map(|(id, _, _)| JointRef {
                        bus: bus.name().to_owned(),
                        id: *id,
                    }));
                    bus.set_targets_under(&targets);
                }
                watchdog.feed(&fed, now);
                stats.commands_applied.fetch_add(1, Ordering::Relaxed);
            }
            Err(why) => {
                stats.commands_dropped.fetch_add(1, Ordering::Relaxed);
                if !said_bad {
                    said_bad = true;
                    tracing::warn!(?scope, "ROS 2: a joint command was dropped whole: {why} (said once; counted in GET /api/v1/ros2)");
                }
                *stats.last_dropped.lock().unwrap_or_else(|p| p.into_inner()) = Some(why);
            }
        }
    }
}

/// One bus's targets, each under the epoch of its joint's stream.
type StreamedTargets = (BusHandle, Vec<(u8, Setpoint, Epoch)>);

/// Commands after this long a pause begin new streams (see [`Streams`]).
const STREAM_RESTART_GAP: Duration = Duration::from_millis(500);

/// Each bus's targets under the epochs of their joints' streams, or why
/// the command is refused whole (a stream an e-stop, a disable, a reset, a
/// fault or a mode change ended).
fn streamed(
    state: &Control,
    streams: &mut Streams,
    per_bus: Vec<commands::BusTargets>,
    restart: bool,
) -> Result<Vec<StreamedTargets>, String> {
    let joints: Vec<JointRef> = per_bus
        .iter()
        .flat_map(|(bus, targets)| {
            targets.iter().map(|(id, _)| JointRef {
                bus: bus.name().to_owned(),
                id: *id,
            })
        })
        .collect();
    let mut epochs = streams
        .admit(state, &joints, restart)
        .map_err(|e| e.to_string())?
        .into_iter();
    Ok(per_bus
        .into_iter()
        .map(|(bus, targets)| {
            let under = targets
                .into_iter()
                .zip(epochs.by_ref())
                .map(|((id, sp), epoch)| (id, sp, epoch))
                .collect();
            (bus, under)
        })
        .collect())
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
