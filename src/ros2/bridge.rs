//! What the bridge declares on one open Zenoh session: one ROS node
//! (`jointd`), per bus (or hand) a `joint_states` publisher, a
//! `joint_commands` and a `joint_trajectory` subscription and the
//! services; per hand also `gripper_command` and `grasp_state`; and a
//! `/diagnostics` publisher; each with its liveliness
//! token so that ROS 2 tools on rmw_zenoh list them. Joint states come from
//! the bus's frame tap (one message per poll round, as recordings);
//! commands go to [`super::command_stream`]. Opening the session, and
//! opening it again, is [`super::supervisor`]'s.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::watch;
use zenoh::liveliness::LivelinessToken;

use super::command_stream::{self, Dropped};
use super::config::{Distro, NamespaceBy, Ros2Config, Ros2Mode};
use super::joint_states::{hand_scopes, publish_joint_states, scopes};
use super::keys::{self, Kind, NodeIdentity};
use super::rosout::Rosout;
use super::services::{self, Service, ServiceQueryable};
use super::{diagnostics, grasp_stream, trajectory_stream};
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;
use crate::record::joint_states::Scope;

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

/// Declares the node, its topics, services and their tokens on
/// `session`, and starts publishing, listening and serving.
pub(super) async fn declare(
    session: &zenoh::Session,
    state: &Arc<Control>,
    cfg: &Ros2Config,
    stats: &Arc<Ros2Stats>,
) -> zenoh::Result<Declared> {
    let (closing, closed) = watch::channel(false);
    // Built as it goes: a declaration refused half-way drops (and so stops)
    // what was started before it.
    let mut on = On::new(session, cfg, closing);
    let token = on.node.node_token();
    on.declared
        .tokens
        .push(session.liveliness().declare_token(token).await?);
    let (publisher, gid) = on.publisher("/rosout", LOG).await?;
    let (rosout, publish_logs) = Rosout::new(&cfg.node_name, publisher, gid);
    on.spawn(publish_logs);
    for (name, scope) in scopes(state, cfg) {
        declare_scope(&mut on, state, cfg, stats, &rosout, &closed, &name, scope).await?;
    }
    // A hand's grasp is the hand's, whichever way the joints' topics are
    // named: namespaced by bus, each hand still gets its grasp topics
    // and services under its own name.
    if cfg.namespace_by == NamespaceBy::Bus {
        for (hand, scope) in hand_scopes(state) {
            let Scope::Hand { joints, .. } = &scope else {
                continue;
            };
            let ns = cfg.namespace(&hand);
            declare_grasp(
                &mut on, state, cfg, stats, &rosout, &ns, &hand, joints, &closed,
            )
            .await?;
            let services = [Service::GraspRelease, Service::GraspStop];
            serve_services(&mut on, state, &scope, &ns, &services, &closed).await?;
        }
    }
    let (publisher, gid) = on.publisher("/diagnostics", DIAGNOSTIC_ARRAY).await?;
    let period = Duration::from_secs_f64(1.0 / cfg.diagnostics_hz);
    on.spawn(diagnostics::publish(
        state.clone(),
        publisher,
        gid,
        period,
        stats.clone(),
    ));
    Ok(on.declared)
}

/// One namespace (a bus, or a hand): `joint_states` published,
/// `joint_commands` and `joint_trajectory` taken, its services served (a
/// hand's grasp too).
#[allow(clippy::too_many_arguments)]
async fn declare_scope(
    on: &mut On<'_>,
    state: &Arc<Control>,
    cfg: &Ros2Config,
    stats: &Arc<Ros2Stats>,
    rosout: &Rosout,
    closed: &watch::Receiver<bool>,
    name: &str,
    scope: Scope,
) -> zenoh::Result<()> {
    let ns = cfg.namespace(name);
    let (publisher, gid) = on
        .publisher(&keys::qualified(&ns, "joint_states"), JOINT_STATE)
        .await?;
    let min_gap = cfg
        .joint_states_max_hz
        .map(|hz| Duration::from_secs_f64(1.0 / hz));
    on.spawn(publish_joint_states(
        state.clone(),
        scope.clone(),
        min_gap,
        publisher,
        gid,
        stats.clone(),
    ));
    let topic = keys::qualified(&ns, "joint_commands");
    let subscriber = on.subscriber(&topic, JOINT_STATE).await?;
    let dropped = Dropped::new(rosout.clone(), topic);
    on.spawn(command_stream::run(
        state.clone(),
        scope.clone(),
        subscriber,
        stats.clone(),
        dropped,
        closed.clone(),
    ));
    let topic = keys::qualified(&ns, "joint_trajectory");
    let subscriber = on.subscriber(&topic, JOINT_TRAJECTORY).await?;
    let dropped = Dropped::new(rosout.clone(), topic);
    on.spawn(trajectory_stream::run(
        state.clone(),
        scope.clone(),
        subscriber,
        stats.clone(),
        dropped,
        closed.clone(),
    ));
    let mut services = vec![Service::Enable, Service::Estop];
    if let Scope::Hand { name: hand, joints } = &scope {
        declare_grasp(on, state, cfg, stats, rosout, &ns, hand, joints, closed).await?;
        services.extend([Service::GraspRelease, Service::GraspStop]);
    }
    serve_services(on, state, &scope, &ns, &services, closed).await?;
    tracing::debug!(%name, %ns, "ROS 2: topics and services declared");
    Ok(())
}

/// Each of `services` under the namespace `ns`, in a task of its own.
async fn serve_services(
    on: &mut On<'_>,
    state: &Arc<Control>,
    scope: &Scope,
    ns: &str,
    services: &[Service],
    closed: &watch::Receiver<bool>,
) -> zenoh::Result<()> {
    for &service in services {
        let (queryable, key) = on.service(ns, service).await?;
        on.spawn(services::serve(
            state.clone(),
            scope.clone(),
            service,
            queryable,
            key,
            closed.clone(),
        ));
    }
    Ok(())
}

/// A hand's grasp: `gripper_command` taken, `grasp_state` published
/// (its services are declared with the others).
#[allow(clippy::too_many_arguments)]
async fn declare_grasp(
    on: &mut On<'_>,
    state: &Arc<Control>,
    cfg: &Ros2Config,
    stats: &Arc<Ros2Stats>,
    rosout: &Rosout,
    ns: &str,
    hand: &str,
    joints: &[(String, u8)],
    closed: &watch::Receiver<bool>,
) -> zenoh::Result<()> {
    let (started, follow) = watch::channel(None);
    let topic = keys::qualified(ns, "gripper_command");
    let subscriber = on.subscriber(&topic, GRIPPER_COMMAND).await?;
    let dropped = Dropped::new(rosout.clone(), topic);
    on.spawn(grasp_stream::run(
        state.clone(),
        hand.to_owned(),
        cfg.grasp_speed_dps,
        subscriber,
        stats.clone(),
        dropped,
        started,
        closed.clone(),
    ));
    let (publisher, gid) = on
        .publisher(&keys::qualified(ns, "grasp_state"), DIAGNOSTIC_ARRAY)
        .await?;
    on.spawn(grasp_stream::publish_state(
        state.clone(),
        hand.to_owned(),
        joints.to_vec(),
        publisher,
        gid,
        follow,
        closed.clone(),
    ));
    Ok(())
}

/// A message type on the network: its DDS name and its type hash.
type RosType = (&'static str, &'static str);
const JOINT_STATE: RosType = (keys::JOINT_STATE_TYPE, keys::JOINT_STATE_HASH);
const JOINT_TRAJECTORY: RosType = (keys::JOINT_TRAJECTORY_TYPE, keys::JOINT_TRAJECTORY_HASH);
const DIAGNOSTIC_ARRAY: RosType = (keys::DIAGNOSTIC_ARRAY_TYPE, keys::DIAGNOSTIC_ARRAY_HASH);
const LOG: RosType = (keys::LOG_TYPE, keys::LOG_HASH);
const GRIPPER_COMMAND: RosType = (keys::GRIPPER_COMMAND_TYPE, keys::GRIPPER_COMMAND_HASH);

/// Declaring on one session: each endpoint with its entity id and token.
struct On<'a> {
    session: &'a zenoh::Session,
    node: NodeIdentity,
    session_gid: [u8; 16],
    entity_id: u32,
    /// Whose key form: Humble's has no type hashes.
    distro: Distro,
    declared: Declared,
}

impl<'a> On<'a> {
    /// Nothing declared yet on `session` for the node `cfg` names;
    /// `closing` tells its tasks when to stop.
    fn new(session: &'a zenoh::Session, cfg: &Ros2Config, closing: watch::Sender<bool>) -> Self {
        let zid = session.zid();
        Self {
            session,
            node: NodeIdentity {
                domain: cfg.domain(),
                session: zid.to_string(),
                node_id: 0,
                namespace: String::new(),
                name: cfg.node_name.clone(),
            },
            session_gid: zid.to_le_bytes(),
            entity_id: 0,
            distro: cfg.distro,
            declared: Declared {
                tokens: Vec::new(),
                tasks: Vec::new(),
                closing,
            },
        }
    }
}

impl On<'_> {
    /// The next entity's id, and its liveliness token declared.
    async fn announce(
        &mut self,
        kind: Kind,
        topic: &str,
        (type_name, hash): RosType,
    ) -> zenoh::Result<u32> {
        self.entity_id += 1;
        let hash = keys::type_hash(self.distro, hash);
        let token = self
            .node
            .endpoint_token(self.entity_id, kind, topic, type_name, hash);
        let token = self.session.liveliness().declare_token(token).await?;
        self.declared.tokens.push(token);
        Ok(self.entity_id)
    }

    fn key(&self, topic: &str, (type_name, hash): RosType) -> String {
        let hash = keys::type_hash(self.distro, hash);
        keys::topic_key(self.node.domain, topic, type_name, hash)
    }

    /// A publisher and its GID.
    async fn publisher(
        &mut self,
        topic: &str,
        ty: RosType,
    ) -> zenoh::Result<(zenoh::pubsub::Publisher<'static>, [u8; 16])> {
        let publisher = self.session.declare_publisher(self.key(topic, ty)).await?;
        let id = self.announce(Kind::Publisher, topic, ty).await?;
        Ok((publisher, keys::gid(&self.session_gid, id)))
    }

    async fn subscriber(&mut self, topic: &str, ty: RosType) -> zenoh::Result<Subscriber> {
        let subscriber = self.session.declare_subscriber(self.key(topic, ty)).await?;
        self.announce(Kind::Subscription, topic, ty).await?;
        Ok(subscriber)
    }

    /// A service's queryable (complete, as rmw_zenoh declares it) and its key.
    async fn service(
        &mut self,
        ns: &str,
        service: Service,
    ) -> zenoh::Result<(ServiceQueryable, String)> {
        let (name, type_name, hash) = service.describe();
        let topic = keys::qualified(ns, name);
        let key = self.key(&topic, (type_name, hash));
        let queryable = self
            .session
            .declare_queryable(key.clone())
            .complete(true)
            .await?;
        self.announce(Kind::Service, &topic, (type_name, hash))
            .await?;
        Ok((queryable, key))
    }

    fn spawn(&mut self, task: impl std::future::Future<Output = ()> + Send + 'static) {
        self.declared.tasks.push(tokio::spawn(task));
    }
}

type Subscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;
