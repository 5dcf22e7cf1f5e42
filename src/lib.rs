//! jointd: a gateway daemon for RS-485 servo joint modules.
//!
//! # Layout
//! - [`protocol`]: pure wire protocol: frames, CRC, typed commands/replies, units, the
//!   parameter table, stream decoder, frames ↔ JSON.
//! - [`cli`]: the `jointd frame …` tools for reading a serial capture by hand.
//! - [`http`]: the HTTP layer: `app(state)`, REST API + OpenAPI, WebSocket, dashboard, auth, errors.
//! - [`daemon`]: `jointd [run]`: config, buses, the HTTP server, graceful shutdown.
//! - [`bus`]: one owner thread per bus, its scheduler, and the handle the API uses.
//! - [`transport`]: the byte lines a bus runs over (tty/pty, in-memory pipe).
//! - [`sim`]: the wire-accurate simulated bus of joint modules (pty or in-memory).
//! - [`rt`]: real-time thread helpers (timer slack, FIFO class) for the bus owner and the simulator.
//! - `bench` (feature `bench`): `jointd bench`: the bus engine against the simulator, measured.

// Visibility says who may use an item: `pub` only where it is reachable from
// outside the crate, `pub(crate)` for the rest; every public type prints in
// a log or a test failure.
#![warn(unreachable_pub, missing_debug_implementations)]

#[cfg(feature = "bench")]
pub mod bench;
pub mod bus;
pub mod cli;
pub mod daemon;
pub mod http;
pub mod protocol;
pub mod rt;
pub mod sim;
pub mod transport;
