//! The ROS 2 bridge's counters ([`crate::ros2`] counts, `GET /api/v1/ros2`
//! and the app state hold them): here, below both, so neither imports the
//! other upwards.

use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::Mutex;

use serde::Serialize;

/// What the bridge did, for `GET /api/v1/ros2`.
#[derive(Debug, Default, Serialize)]
pub struct Ros2Stats {
    /// A Zenoh session is open and (in client mode) a router reachable.
    pub connected: AtomicBool,
    /// Sessions opened since start (reconnections included).
    pub connects: AtomicU64,
    /// Why the latest attempt failed or the latest session was lost.
    pub last_error: Mutex<Option<String>>,
    pub joint_states: AtomicU64,
    pub diagnostics: AtomicU64,
    pub commands_applied: AtomicU64,
    /// Commands refused whole (unknown joint, out of limits, NaN, ...).
    pub commands_dropped: AtomicU64,
    /// Why the latest one was.
    pub last_dropped: Mutex<Option<String>>,
    /// Times the command stream stopped and `[watchdog]` acted.
    pub watchdog_fired: AtomicU64,
    /// Frames the bridge fell too far behind to see.
    pub frames_lost: AtomicU64,
    pub publish_errors: AtomicU64,
}
