//! `<ns>/joint_trajectory` (`trajectory_msgs/msg/JointTrajectory`): each
//! message is a move ([`crate::control::moves`], as `POST /api/v1/moves`
//! starts one) through its points, each reached at its `time_from_start`
//! from the moment it arrives, the joints named as in `joint_commands`. The
//! path is checked whole (soft limits, speed limits, enabled joints,
//! position mode) before any joint moves; a refused trajectory is dropped
//! whole, counted and said as a dropped command is. The move is
//! [`super::trajectory`]'s.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use tokio::sync::watch;

use super::audit;
use super::command_stream::{next_payload, Dropped, Subscriber};
use super::commands::{joints_named, Refused};
use super::trajectory::move_request;
use crate::control::moves;
use crate::control::ros2_stats::Ros2Stats;
use crate::control::Control;
use crate::record::joint_states::Scope;
use crate::rosmsg::bridge::JointTrajectory;

/// Takes trajectories until the session closes.
pub(super) async fn run(
    state: Arc<Control>,
    scope: Scope,
    subscriber: Subscriber,
    stats: Arc<Ros2Stats>,
    mut dropped: Dropped,
    mut closing: watch::Receiver<bool>,
) {
    loop {
        let Some(payload) = next_payload(&subscriber, &mut closing).await else {
            return;
        };
        let started = match JointTrajectory::from_cdr(&payload) {
            Ok(t) => start(&state, &scope, &t).await,
            Err(e) => Err(Refused::new(
                "not-cdr",
                format!("not a trajectory_msgs/msg/JointTrajectory in CDR: {e}"),
            )),
        };
        let what = format!("topic {}", dropped.topic);
        audit::tell(
            &state,
            audit::bus(&scope),
            &what,
            if started.is_ok() {
                "started a move"
            } else {
                "refused"
            },
        );
        match started {
            Ok(id) => {
                stats.commands_applied.fetch_add(1, Ordering::Relaxed);
                tracing::info!(
                    move_id = id,
                    ?scope,
                    "ROS 2: a joint trajectory started a move"
                );
            }
            Err(refused) => dropped.say(&stats, "a joint trajectory", refused),
        }
    }
}

/// Starts the trajectory's move; its id.
async fn start(state: &Arc<Control>, scope: &Scope, t: &JointTrajectory) -> Result<u64, Refused> {
    let joints = joints_named(state, scope, &t.joint_names)?;
    let req = move_request(t, joints)?;
    Ok(moves::start(state, &req).await?.id)
}
