//! One owner per bus: a dedicated OS thread holds the port, schedules every
//! frame and publishes what it learns; the rest of the daemon uses a
//! [`handle::BusHandle`].
//!
//! # Layout
//! - [`handle`]: the cloneable handle, setpoint store, requests, snapshots, events.
//! - [`error`]: the bus errors, one HTTP status each.

pub mod error;
pub mod handle;

pub use error::BusError;
pub use handle::{BusHandle, BusSnapshot, Setpoint, Targets};
