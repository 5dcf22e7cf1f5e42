//! REST of the ROS 2 bridge: whether it runs, and what it did.

use std::sync::atomic::Ordering;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::http::error::ApiResult;
use crate::http::state::AppState;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(ros2_status))
}

/// The ROS 2 bridge's counters.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Ros2View {
    /// The bridge runs (`--ros2` or `[ros2] enabled`).
    #[schema(example = true)]
    pub enabled: bool,
    /// This build has the bridge (cargo feature `ros2`).
    #[schema(example = true)]
    pub built: bool,
    /// A Zenoh session is open and, in client mode, its router reachable.
    /// The bridge retries in the background (0.5 s doubling to 30 s) while
    /// it is not; the daemon serves regardless.
    #[schema(example = true)]
    pub connected: bool,
    /// Sessions opened since start (a reconnection counts again).
    #[schema(example = 1)]
    pub connects: u64,
    /// Why the latest attempt to connect failed, or the latest session was lost.
    #[schema(example = "Unable to connect to any of [tcp/127.0.0.1:7447]!")]
    pub last_error: Option<String>,
    /// `JointState` messages published (all buses).
    #[schema(example = 12840)]
    pub joint_states: u64,
    /// `DiagnosticArray` messages published.
    #[schema(example = 197)]
    pub diagnostics: u64,
    /// `joint_commands` applied.
    #[schema(example = 5021)]
    pub commands_applied: u64,
    /// `joint_commands` refused whole (unknown joint, out of limits, NaN, not enabled).
    #[schema(example = 1)]
    pub commands_dropped: u64,
    /// Why the latest one was refused.
    #[schema(example = "no joint named `pinky` on bus `sim0`")]
    pub last_dropped: Option<String>,
    /// Times the command stream stopped and `[watchdog]` acted.
    #[schema(example = 0)]
    pub watchdog_fired: u64,
    /// Frames the bridge fell too far behind to see.
    #[schema(example = 0)]
    pub frames_lost: u64,
    #[schema(example = 0)]
    pub publish_errors: u64,
}

/// The ROS 2 bridge: whether it runs and what it did.
///
/// Whether it is connected to the Zenoh network (with the latest error),
/// and counts of messages published and commands taken or refused (with
/// the latest reason), since the daemon started; all zero when it does not
/// run.
#[utoipa::path(get, path = "/api/v1/ros2", tag = TAG_CONTROL,
    responses((status = 200, description = "The bridge's counters", body = Ros2View), ErrorResponses))]
async fn ros2_status(State(state): State<AppState>) -> ApiResult<Json<Ros2View>> {
    let stats = state.control().ros2();
    let n = |f: fn(&crate::control::ros2_stats::Ros2Stats) -> &std::sync::atomic::AtomicU64| {
        stats.map_or(0, |s| f(s).load(Ordering::Relaxed))
    };
    Ok(Json(Ros2View {
        enabled: stats.is_some(),
        built: cfg!(feature = "ros2"),
        connected: stats.is_some_and(|s| s.connected.load(Ordering::Relaxed)),
        connects: n(|s| &s.connects),
        last_error: stats.and_then(|s| {
            s.last_error
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clone()
        }),
        joint_states: n(|s| &s.joint_states),
        diagnostics: n(|s| &s.diagnostics),
        commands_applied: n(|s| &s.commands_applied),
        commands_dropped: n(|s| &s.commands_dropped),
        last_dropped: stats.and_then(|s| {
            s.last_dropped
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clone()
        }),
        watchdog_fired: n(|s| &s.watchdog_fired),
        frames_lost: n(|s| &s.frames_lost),
        publish_errors: n(|s| &s.publish_errors),
    }))
}
