//! The control core: every way to move a joint (REST, WebSocket, ROS 2,
//! moves, poses, homing) goes through here, as equals. It owns the soft
//! limits and target checks, moves, homing, calibration, the teleop
//! watchdog policy and its one joint reference type; it speaks its own
//! error ([`ControlError`]), which each front-end maps once. Whether a
//! frame may still go out is decided below it, by the bus owner's motion
//! authority ([`crate::bus::authority`]): the core admits a command under a
//! joint's epoch, the owner drops it once that epoch has passed.
//!
//! Request types (a target, a move, a homing job, a grasp) carry their
//! OpenAPI schema (`utoipa::ToSchema`) beside their serde shape, here: the
//! type that parses a request is the one the document describes, so the
//! two cannot drift, and REST, WebSocket and ROS 2 keep one vocabulary. A
//! REST-side copy of each would be a second definition to keep in step.
//! The derive is metadata only: nothing in the core calls into utoipa.
//!
//! # Layout
//! One-way layers: each file imports only from files above it in this list.
//! - [`error`]: [`ControlError`], typed refusals with the field and range at fault.
//! - [`device`]: what a device's published state says (firmware, angle, enabled).
//! - `current_limit`: a current limit lowered by a routine, written back, or owed until it is.
//! - [`ros2_stats`]: the ROS 2 bridge's counters (read by `/metrics` and `/api/v1/ros2`).
//! - [`foxglove_stats`]: the live Foxglove view's counters (read by `/metrics`).
//! - [`estop`]: the e-stop's fan-out over buses and its report.
//! - [`joints`]: [`JointRef`], device ids, a device known on its bus.
//! - [`revision`]: features a firmware revision must have (422, or 409 while unknown).
//! - [`limits`]: per-joint soft limits from the config.
//! - [`teleop`]: the watchdog policy, its default, and what firing it does.
//! - [`targets`]: physical targets → raw setpoints, checked; admission under the authority.
//! - `audit`: who changed what, by token name, told to the log and the buses' events.
//! - [`books`]: what runs now, one book per kind of job (moves, homing, grasps,
//!   recordings, teleop streams).
//! - [`velocity`]: a velocity command as a position target toward the soft limit at that speed.
//! - `state`: [`Control`], the state the core works on: buses, limits, options, books.
//! - `lookup`: a hand by name, a joint by bus and id or by hand and joint name.
//! - [`bus_reader`]: a bus as a front-end sees it, read only.
//! - `bus_ops`: scan, baud, blocks read now, parameters written, flash, a new id.
//! - `doctor`: the doctor's checks of a running bus, on the port its owner lends.
//! - `actions`: enable, disable, mode, jog, re-zero, targets and e-stop, as every
//!   front-end offers them, checked here.
//! - `calibration`: saving a joint's calibration (REST and homing).
//! - `recordings`: recordings started, listed, stopped; their files.
//! - `grasp/`: closing a hand's fingers on an object and holding it with a
//!   set current (its own layout in `grasp/mod.rs`).
//! - [`watchdog`]: the one teleop watchdog (WebSocket connections and the ROS 2 bridge).
//! - `batch`: one resolver of target batches for the teleop front-ends (WebSocket, ROS 2).
//! - [`streams`]: teleop streams, each under the epoch it began with; ended streams stay ended.
//! - [`moves`]: moves checked whole, started, stopped.
//! - `handoff`: a move out of a holding grasp leaves once the grasp handed the
//!   joint's current limit back (held where it stands till then).
//! - `homing/`: homing jobs, one per joint, bounded (its own layout in `homing/mod.rs`).
//! - `poses`: going to a hand's saved pose (a move of its joints).
//! - this file: the layout and what the rest of the daemon uses by a short name.

pub(crate) mod actions;
pub(crate) mod audit;
pub(crate) mod batch;
pub mod books;
pub(crate) mod bus_ops;
pub mod bus_reader;
pub(crate) mod calibration;
pub(crate) mod current_limit;
pub mod device;
pub(crate) mod doctor;
pub mod error;
pub mod estop;
pub mod foxglove_stats;
pub(crate) mod grasp;
pub(crate) mod handoff;
pub(crate) mod homing;
pub mod joints;
pub mod limits;
pub(crate) mod lookup;
pub mod moves;
pub(crate) mod poses;
pub(crate) mod recordings;
pub mod revision;
pub mod ros2_stats;
mod state;
pub mod streams;
pub mod targets;
pub mod teleop;
// Its one user so far is the ROS 2 bridge (cargo feature `ros2`).
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod velocity;
pub mod watchdog;

pub use error::{ControlError, ControlResult};
pub use joints::JointRef;
pub use state::{Control, Options};
