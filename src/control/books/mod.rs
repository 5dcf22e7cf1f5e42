//! The books of what runs now, one per kind of job: moves, homing jobs,
//! grasps, recordings and teleop streams. The core's state holds them,
//! the jobs write them, `GET` and the dashboard read them. Each is kept
//! under a std `Mutex` never held across an `.await`.
//!
//! # Layout
//! - `lock`: a slot's lock, taken even when poisoned.
//! - `moves`, `homing`, `grasps`, `recordings`, `streams`: one book each.

pub(crate) mod grasps;
pub(crate) mod homing;
pub(crate) mod lock;
pub(crate) mod moves;
pub(crate) mod recordings;
pub mod streams;
