//! One namespace's `joint_commands` subscription as a teleoperation
//! stream: each command checked whole ([`super::commands`]), admitted under
//! the joints' motion epochs ([`Streams`]) and applied; the `[watchdog]`
//! over the stream, fired when commands stop and when the session goes.
//! Velocity commands head for a soft limit until told otherwise, so a
//! stream that sends them is always watched, at most [`VELOCITY_HOLD`]
//! (whatever `[watchdog]` says, even off).

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::watch;

use super::audit;
use super::commands::{self, Refused};
use super::rosout::Rosout;
use crate::bus::Source;
use crate::control::books::streams::{Driver, Via};
use crate::control::ros2_stats::Ros2Stats;
use crate::control::streams::Streams;
use crate::control::watchdog::{fire_policy, Watchdog};
use crate::control::Control;
use crate::record::joint_states::Scope;
use crate::rosmsg::JointState;

pub(super) type Subscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// The next message's bytes on a topic the bridge takes commands from;
/// `None` once the subscription or the bridge ends.
pub(super) async fn next_payload(
    subscriber: &Subscriber,
    closing: &mut watch::Receiver<bool>,
) -> Option<Vec<u8>> {
    tokio::select! {
        s = subscriber.recv_async() => s.ok().map(|s| s.payload().to_bytes().into_owned()),
        // The guard `wait_for` returns is not `Send`: dropped at once.
        () = async { drop(closing.wait_for(|c| *c).await) } => None,
    }
}

/// The longest a stream of velocity commands may pause before its joints
/// are stopped (`[watchdog]`'s policy; hold when it has none): a
/// ros2_control loop sends at 50 Hz or more.
const VELOCITY_HOLD: Duration = Duration::from_millis(300);

/// Commands after this long a pause begin new streams (see [`Streams`]).
const STREAM_RESTART_GAP: Duration = Duration::from_millis(500);

/// Takes commands until the session closes (`closing` turns `true` or the
/// subscription ends); then the watchdog's policy applies to the joints the
/// stream drove, as when a WebSocket client goes away.
pub(super) async fn run(
    state: Arc<Control>,
    scope: Scope,
    subscriber: Subscriber,
    stats: Arc<Ros2Stats>,
    dropped: Dropped,
    mut closing: watch::Receiver<bool>,
) {
    let mut stream = CommandStream::new(&state, scope, stats, dropped);
    loop {
        match stream.next(&subscriber, &mut closing).await {
            Next::Sample(sample) => stream.take(&sample.payload().to_bytes()).await,
            Next::Fired | Next::Looked => {}
            Next::Closed => break,
        }
    }
    stream.fire("the ROS 2 session closed").await;
}

/// How often the stream looks whether one of its joints' streams was
/// ended, while it has live ones: an atomic read per joint.
const STREAM_CHECK: Duration = Duration::from_millis(10);

/// What waiting for a command came to.
enum Next {
    Sample(zenoh::sample::Sample),
    /// Commands stopped for longer than the hold timeout: the watchdog fired.
    Fired,
    /// Looked whether a stream was ended (an e-stop, a disable...), so the
    /// stream book stops showing it at once, not at the next command.
    Looked,
    /// The session is closing, or the subscription ended.
    Closed,
}

/// The state of one subscription's stream.
struct CommandStream {
    state: Arc<Control>,
    scope: Scope,
    stats: Arc<Ros2Stats>,
    watchdog: Watchdog,
    /// The hold timeout the watchdog is armed with (`None`: disarmed).
    hold: Option<Duration>,
    streams: Streams,
    last_command: Option<tokio::time::Instant>,
    dropped: Dropped,
}

/// Where dropped commands are said.
pub(super) struct Dropped {
    pub rosout: Rosout,
    /// The topic the commands came on.
    pub topic: String,
    /// The daemon's log has said one (it says the first only).
    pub logged: bool,
}

impl Dropped {
    pub(super) fn new(rosout: Rosout, topic: String) -> Self {
        Self {
            rosout,
            topic,
            logged: false,
        }
    }

    /// Counts a command refused whole, keeps why, says it on `/rosout`
    /// (throttled per cause) and, the first time, in the daemon's log.
    pub(super) fn say(&mut self, stats: &Ros2Stats, what: &str, refused: Refused) {
        stats.commands_dropped.fetch_add(1, Ordering::Relaxed);
        let msg = format!("{what} on {} dropped whole: {}", self.topic, refused.why);
        if !std::mem::replace(&mut self.logged, true) {
            tracing::warn!(cause = %refused.cause, "ROS 2: {msg} (said once here; on /rosout once per cause per 5 s; counted in GET /api/v1/ros2)");
        }
        self.rosout.warn(&refused.cause, msg);
        *stats.last_dropped.lock().unwrap_or_else(|p| p.into_inner()) = Some(refused.why);
    }
}

impl CommandStream {
    fn new(state: &Arc<Control>, scope: Scope, stats: Arc<Ros2Stats>, dropped: Dropped) -> Self {
        // The one teleop watchdog, as a WebSocket client gets it by default.
        let default = state.watchdog_default();
        let hold = Duration::from_millis(default.hold_timeout_ms);
        let mut watchdog = Watchdog::default();
        watchdog.arm(hold, default.policy, tokio::time::Instant::now());
        let shown = state.stream_book().register(Driver {
            via: Via::Ros2,
            client: 0,
            name: Some(format!("ROS 2 {}", dropped.topic)),
        });
        Self {
            state: state.clone(),
            scope,
            stats,
            watchdog,
            hold: (!hold.is_zero()).then_some(hold),
            streams: Streams::shown_as(shown),
            last_command: None,
            dropped,
        }
    }

    /// Waits for the next command, firing the watchdog if it is due first.
    async fn next(&mut self, subscriber: &Subscriber, closing: &mut watch::Receiver<bool>) -> Next {
        let deadline = self.watchdog.deadline();
        let due = async {
            match deadline {
                Some(d) => tokio::time::sleep_until(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            sample = subscriber.recv_async() => match sample {
                Ok(s) => Next::Sample(s),
                Err(_) => Next::Closed,
            },
            // The guard `wait_for` returns is not `Send`: dropped at once.
            () = async { drop(closing.wait_for(|c| *c).await) } => Next::Closed,
            () = due => {
                self.fire("joint commands stopped").await;
                Next::Fired
            }
            () = tokio::time::sleep(STREAM_CHECK), if self.streams.any_live() => {
                self.streams.end_revoked(&self.state);
                Next::Looked
            }
        }
    }

    /// Applies the watchdog's policy to the joints the stream drove, if it
    /// is armed and has not fired since the last command.
    async fn fire(&mut self, why: &str) {
        if let Some((policy, joints)) = self.watchdog.fire() {
            tracing::warn!(?joints, ?policy, "ROS 2: {why}: watchdog");
            fire_policy(&self.state, policy, &joints).await;
            self.stats.watchdog_fired.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// One command: applied whole, or refused whole and counted.
    async fn take(&mut self, bytes: &[u8]) {
        let now = tokio::time::Instant::now();
        // A ROS 2 topic has no way to ask for a new stream: commands after
        // a pause begin one; a controller streaming on through an e-stop and
        // a later enable does not drive the joints again until it pauses.
        let restart = self
            .last_command
            .map_or(true, |at| now.duration_since(at) >= STREAM_RESTART_GAP);
        self.last_command = Some(now);
        let cmd = match JointState::from_cdr(bytes) {
            Ok(cmd) => cmd,
            Err(e) => {
                let why = format!("not a sensor_msgs/msg/JointState in CDR: {e}");
                return self.dropped(Refused::new("not-cdr", why));
            }
        };
        let outcome = commands::targets(&self.state, &self.scope, &cmd).and_then(|items| {
            self.streams
                .apply(&self.state, &items, restart, Source::Ros2)
                .map_err(Refused::from)
        });
        match outcome {
            Ok(applied) => {
                if commands::by_velocity(&cmd) {
                    self.watch_velocities(now);
                }
                self.watchdog.feed(&applied.joints, now);
                self.stats.commands_applied.fetch_add(1, Ordering::Relaxed);
                self.tell("applied");
            }
            Err(why) => {
                self.tell("refused");
                self.dropped(why);
            }
        }
    }

    /// Puts the command in the audit (repeats at stream rates collapse to
    /// one line a second there).
    fn tell(&self, outcome: &str) {
        let what = format!("topic {}", self.dropped.topic);
        audit::tell(&self.state, audit::bus(&self.scope), &what, outcome);
    }

    /// Arms the watchdog with at most [`VELOCITY_HOLD`].
    fn watch_velocities(&mut self, now: tokio::time::Instant) {
        if self.hold.is_some_and(|h| h <= VELOCITY_HOLD) {
            return;
        }
        let policy = self.state.watchdog_default().policy;
        self.watchdog.arm(VELOCITY_HOLD, policy, now);
        self.hold = Some(VELOCITY_HOLD);
    }

    fn dropped(&mut self, refused: Refused) {
        self.dropped.say(&self.stats, "a joint command", refused);
    }
}
