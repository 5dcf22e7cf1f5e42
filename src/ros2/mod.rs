//! ROS 2 over Zenoh: `sensor_msgs/msg/JointState` on
//! `/<namespace>/joint_states` per bus at the telemetry rate,
//! `diagnostic_msgs/msg/DiagnosticArray` on `/diagnostics`, and
//! `/<namespace>/joint_commands` taken as setpoints, `joint_trajectory` as
//! moves, the services `enable` and `estop`, per hand a grasp
//! (`gripper_command`, `grasp_state`, `grasp_release`, `grasp_stop`),
//! `/rosout` for dropped commands; named, encoded and
//! announced as `rmw_zenoh` does, so ROS 2 nodes on rmw_zenoh (and `ros2
//! topic list` / `echo`) see them with no bridge of their own.
//!
//! - [`config`]: the `[ros2]` table;
//! - [`keys`]: key expressions, liveliness tokens, attachments, type
//!   hashes (the design document is cited there);
//! - [`commands`]: a command checked whole and turned into setpoints;
//! - [`trajectory`]: a `JointTrajectory` as a move request;
//! - [`gripper`]: a `GripperCommand` as a grasp request, a grasp as
//!   `DiagnosticStatus`es;
//! - [`throttle`]: each cause on `/rosout` at most once per 5 s;
//! - [`link`]: when to try the router again and what to log about it;
//! - with the cargo feature `ros2` (Zenoh adds minutes to a cold build):
//!   `supervisor` (the one background task: the session, opened and opened
//!   again), `bridge` (publishers, subscriptions and tokens on a session),
//!   `command_stream` (one `joint_commands` subscription as a teleop stream),
//!   `joint_states` (published per namespace), `trajectory_stream` (`joint_trajectory` as moves), `grasp_stream`
//!   (`gripper_command` as grasps, `grasp_state`), `services`
//!   (`enable`, `estop`, `grasp_release`, `grasp_stop`), `rosout`, `diagnostics` (per bus and per joint),
//!   `audit` (its commands told as `ros2`: ROS 2 carries no tokens).
//!
//! The bridge never holds the daemon: without a router the buses and the
//! API serve as ever, and `GET /api/v1/ros2` says `connected: false`.
//!
//! Messages are CDR, encoded and decoded by [`crate::rosmsg`] (shared with
//! MCAP recordings).
//! Positions are rad, velocities rad/s at the output shaft, and **effort is
//! the q-axis current in A**, in each joint's calibrated frame.

// Pure, so tested without the `ros2` feature; only the bridge uses them.
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod commands;
pub mod config;
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod gripper;
pub mod keys;
pub mod link;
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod throttle;
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod trajectory;

#[cfg(feature = "ros2")]
mod audit;
#[cfg(feature = "ros2")]
mod bridge;
#[cfg(feature = "ros2")]
mod command_stream;
#[cfg(feature = "ros2")]
mod diagnostics;
#[cfg(feature = "ros2")]
mod grasp_stream;
#[cfg(feature = "ros2")]
mod joint_states;
#[cfg(feature = "ros2")]
mod rosout;
#[cfg(feature = "ros2")]
mod services;
#[cfg(feature = "ros2")]
mod supervisor;
#[cfg(feature = "ros2")]
mod trajectory_stream;

use std::sync::Arc;

use thiserror::Error;

pub use config::{Ros2Config, Ros2Mode};

pub use crate::control::ros2_stats::Ros2Stats;

#[derive(Debug, Error)]
pub enum Ros2Error {
    #[error("--ros2 / [ros2] enabled: this jointd was built without the `ros2` feature (cargo build --features ros2)")]
    NotBuilt,
    #[error("ROS 2 bridge (Zenoh): {0}")]
    Zenoh(String),
}

/// The running bridge; dropping it leaves the ROS graph.
#[cfg(feature = "ros2")]
#[derive(Debug)]
pub struct Bridge {
    supervisor: tokio::task::JoinHandle<()>,
}

#[cfg(feature = "ros2")]
impl Drop for Bridge {
    fn drop(&mut self) {
        // The session and its tokens go with the task.
        self.supervisor.abort();
    }
}

/// Without the `ros2` feature there is no bridge to run.
#[cfg(not(feature = "ros2"))]
#[derive(Debug)]
pub struct Bridge;

/// Starts the bridge for every bus of `state` in the background: it
/// connects (and reconnects) on its own; only a configuration Zenoh
/// refuses is an error here.
#[cfg(feature = "ros2")]
pub fn start(
    state: Arc<crate::control::Control>,
    cfg: Ros2Config,
    stats: Arc<Ros2Stats>,
) -> Result<Bridge, Ros2Error> {
    let zenoh_cfg = bridge::session_config(&cfg).map_err(|e| Ros2Error::Zenoh(e.to_string()))?;
    let supervisor = tokio::spawn(supervisor::supervise(state, cfg, zenoh_cfg, stats));
    Ok(Bridge { supervisor })
}

/// Without the `ros2` feature: says so.
#[cfg(not(feature = "ros2"))]
pub fn start(
    _state: Arc<crate::control::Control>,
    _cfg: Ros2Config,
    _stats: Arc<Ros2Stats>,
) -> Result<Bridge, Ros2Error> {
    Err(Ros2Error::NotBuilt)
}

/// Whether this build has the bridge.
pub const BUILT: bool = cfg!(feature = "ros2");
