//! A hand's grasp over ROS 2: `<hand>/gripper_command`
//! (`control_msgs/msg/GripperCommand`) starts a grasp of the hand through
//! [`crate::control::grasp::start`], as `POST /api/v1/hands/{hand}/grasp`
//! does ([`super::gripper`] turns the message into the request); a
//! refused command is dropped, counted and said on `/rosout` as a dropped
//! joint command is. `<hand>/grasp_state` (`diagnostic_msgs/msg/
//! DiagnosticArray`, [`super::gripper::statuses`]) follows the hand's
//! grasp, however it was started (ROS 2, REST, WebSocket), published when
//! it changes and once a second while it runs.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use tokio::sync::watch;

use super::audit;
use super::command_stream::{next_payload, Dropped, Subscriber};
use super::commands::Refused;
use super::gripper::{self, FingerNow};
use super::keys;
use crate::control::grasp;
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;
use crate::record::joint_states::system_ns;
use crate::rosmsg::bridge::GripperCommand;
use crate::rosmsg::diagnostic_array_cdr;

/// How often the hand's grasp is looked at for a change.
const LOOK: Duration = Duration::from_millis(50);
/// A running grasp's state is published at least this often (for a
/// subscriber that came late).
const REPEAT: Duration = Duration::from_secs(1);

/// The grasp a hand's joints are in, if any is running.
pub(super) fn running(state: &Control, joints: &[(String, u8)]) -> Option<u64> {
    joints
        .iter()
        .find_map(|(bus, id)| state.grasps().running_job(bus, *id))
}

/// Takes gripper commands until the session closes; each grasp started
/// is told to `started` (the state publisher follows it at once, even if
/// it ends before its next look).
#[allow(clippy::too_many_arguments)]
pub(super) async fn run(
    state: Arc<Control>,
    hand: String,
    speed_dps: f64,
    subscriber: Subscriber,
    stats: Arc<Ros2Stats>,
    mut dropped: Dropped,
    started: watch::Sender<Option<u64>>,
    mut closing: watch::Receiver<bool>,
) {
    loop {
        let Some(payload) = next_payload(&subscriber, &mut closing).await else {
            return;
        };
        let outcome = match GripperCommand::from_cdr(&payload) {
            Ok(cmd) => start(&state, &hand, &cmd, speed_dps).await,
            Err(e) => Err(Refused::new(
                "not-cdr",
                format!("not a control_msgs/msg/GripperCommand in CDR: {e}"),
            )),
        };
        let what = format!("topic {}", dropped.topic);
        audit::tell(
            &state,
            None,
            &what,
            if outcome.is_ok() {
                "started a grasp"
            } else {
                "refused"
            },
        );
        match outcome {
            Ok(id) => {
                stats.commands_applied.fetch_add(1, Ordering::Relaxed);
                started.send_replace(Some(id));
                tracing::info!(grasp_id = id, %hand, "ROS 2: a gripper command started a grasp");
            }
            Err(refused) => dropped.say(&stats, "a gripper command", refused),
        }
    }
}

/// Starts the grasp `cmd` asks of `hand`; its id.
async fn start(
    state: &Arc<Control>,
    hand: &str,
    cmd: &GripperCommand,
    speed_dps: f64,
) -> Result<u64, Refused> {
    let fingers = fingers_now(state, hand);
    let req = gripper::grasp_request(cmd, &fingers, speed_dps)?;
    Ok(grasp::start(state, hand, &req).await?.id)
}

/// The hand's fingers.
fn fingers_now(state: &Control, hand: &str) -> Vec<FingerNow> {
    let Some(h) = state.hands().and_then(|s| s.hand(hand)).cloned() else {
        return Vec::new();
    };
    h.joints
        .iter()
        .map(|j| FingerNow {
            name: j.name.clone(),
        })
        .collect()
}

/// Publishes the hand's grasp state until the session closes.
pub(super) async fn publish_state(
    state: Arc<Control>,
    hand: String,
    joints: Vec<(String, u8)>,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    mut started: watch::Receiver<Option<u64>>,
    mut closing: watch::Receiver<bool>,
) {
    let mut followed: Option<u64> = None;
    let mut last: Option<(gripper::Change, tokio::time::Instant)> = None;
    let mut sequence = 0i64;
    let mut tick = tokio::time::interval(LOOK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            changed = started.changed() => {
                if changed.is_err() {
                    return;
                }
            }
            () = async { drop(closing.wait_for(|c| *c).await) } => return,
        }
        // A grasp just started here, or any grasp running on the hand.
        let newest = (*started.borrow_and_update()).filter(|id| Some(*id) > followed);
        if let Some(id) = newest.or_else(|| running(&state, &joints)) {
            if followed != Some(id) {
                followed = Some(id);
                last = None;
            }
        }
        let Some(view) = followed.and_then(|id| state.grasps().view(id)) else {
            continue;
        };
        let now = tokio::time::Instant::now();
        let key = gripper::change(&view);
        let due = match &last {
            None => true,
            Some((k, at)) => *k != key || (view.state == "running" && now >= *at + REPEAT),
        };
        if !due {
            continue;
        }
        last = Some((key, now));
        sequence += 1;
        let ns = i64::try_from(system_ns(SystemTime::now())).unwrap_or(i64::MAX);
        let cdr = diagnostic_array_cdr(
            u64::try_from(ns).unwrap_or(0),
            &hand,
            &gripper::statuses(&view),
        );
        let put = publisher
            .put(cdr)
            .attachment(keys::attachment(sequence, ns, &gid));
        if let Err(e) = put.await {
            tracing::debug!(error = %e, %hand, "ROS 2: a grasp state could not be published");
        }
    }
}
