//! jointd: a gateway daemon for RS-485 servo joint modules.
//!
//! # Layout
//! - [`protocol`]: pure wire protocol: frames, CRC, typed commands/replies, units, stream decoder.
//! - [`frame_json`]: frames ↔ JSON with the field names of `vectors.json` (CLI, API, tests).
//! - [`cli`]: the `jointd frame …` tools for reading a serial capture by hand.

pub mod cli;
pub mod frame_json;
pub mod protocol;
