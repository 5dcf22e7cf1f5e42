//! Writing behind a USB-serial adapter: it holds host bytes until its next
//! USB (micro)frame and replies for a frame or a latency timer, so the
//! owner writes ahead of the replies it has not seen yet, timed to the
//! wire, and proves (or bounds) when each write reached the line.
//!
//! # Layout
//! One-way: each file imports only from files above it; all are pure
//! (every instant is passed in).
//! - [`frame_clock`]: the adapter's USB frame boundaries, inferred from reply arrivals.
//! - [`guard`]: how far blind writes are trusted, learnt from collisions' aftermath.
//! - [`confirm`]: confirmed writes: the port's output count says when the adapter took each.
//! - [`pipeline`]: the polls written ahead (replies in flight), built on the three above;
//!   its side of confirmed writes in `pipeline_confirmed.rs`.

pub(crate) mod confirm;
pub(crate) mod frame_clock;
pub mod guard;
pub(crate) mod pipeline;
