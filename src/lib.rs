//! jointd: a gateway daemon for RS-485 servo joint modules.
//!
//! # Layout
//! - [`protocol`]: pure wire protocol: frames, CRC, typed commands/replies, units, stream decoder.
//! - [`frame_json`]: frames ↔ JSON with the field names of `vectors.json` (CLI, API, tests).
//! - [`cli`]: the `jointd frame …` tools for reading a serial capture by hand.
//! - [`api`]: the REST API (axum routers over the bus handles, OpenAPI, auth, soft limits).
//! - [`daemon`]: `jointd [run]`: config, buses, the HTTP server, graceful shutdown.
//! - [`bus`]: one owner thread per bus, its scheduler, and the handle the API uses.
//! - [`transport`]: the byte lines a bus runs over (tty/pty, in-memory pipe).
//! - [`ws`]: the WebSocket endpoint: telemetry streams, batch setpoints, teleop watchdog.
//! - [`web`]: the embedded dashboard (or `--web-dir` while developing).
//! - [`sim`]: the wire-accurate simulated bus of joint modules (pty or in-memory).
//! - [`rt`]: real-time thread helpers (timer slack, FIFO class) for the bus owner and the simulator.
//! - [`bench`]: `jointd bench`: the bus engine against the simulator, measured.

pub mod api;
pub mod bench;
pub mod bus;
pub mod cli;
pub mod daemon;
pub mod frame_json;
pub mod protocol;
pub mod rt;
pub mod sim;
pub mod transport;
pub mod web;
pub mod ws;
