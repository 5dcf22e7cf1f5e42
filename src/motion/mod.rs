//! Motion generated in the daemon: a move of several joints,
//! possibly on several buses, as one synchronised path that each bus's
//! owner samples at every control cycle, at the wire time of the frame it
//! plans, so the setpoints carry no client jitter.
//!
//! - [`path`]: the pure paths: shapes (linear, minimum-jerk, trapezoidal
//!   velocity), durations from velocity and acceleration limits, waypoints.
//! - [`run`]: a move in progress as every party sees it: its joints, its
//!   state (running, done, stopped, aborted with a reason) and progress.

pub mod path;
pub mod run;

pub use path::{Method, Path, PathError, Sample};
pub use run::{MoveState, MoveStatus, RunningMove};
