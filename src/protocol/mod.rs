//! The joint-module wire protocol, as pure functions of bytes.
//!
//! This module is the one place that knows frame offsets, CRC rules and unit
//! scaling (the protocol's SPEC.md, cited by section). It does no I/O and
//! depends on no runtime, so the daemon and the simulator share it, and the
//! tests prove it against the protocol's test vectors (a copy in
//! `tests/data/vectors.json`).
//!
//! # Layout
//! - [`checksum`]: the CRC-16/IBM-3740 used by both frame kinds.
//! - [`frame`]: 20-byte standard and broadcast frames, encode/decode with CRC check.
//! - [`frame_json`]: frames ↔ JSON with the field names of `vectors.json` (CLI, API, tests).
//! - [`command`]: typed host→device commands (control, jog, config, broadcasts).
//! - [`reply`]: typed device→host replies (INFO_01..07, RES), raw bytes always kept.
//! - [`ids`]: which device ids the wire can address, and id lists as people write them.
//! - [`params`]: the parameter table: one row per config/INFO index, everything else derives from it.
//! - [`message`]: classifies a decoded standard frame as a command or a reply.
//! - [`units`]: every raw ↔ physical conversion, range-checked.
//! - [`values`]: the enumerated values frames and parameters carry (INFO block, mode, baud level).
//! - [`status`]: names of fsm states and fault codes, defined once.
//! - [`stream`]: finds frames in a byte stream, resyncing past garbage.
//! - [`error`]: the typed errors of this layer.

pub mod checksum;
pub mod command;
pub mod error;
pub mod frame;
pub mod frame_json;
pub mod ids;
pub mod message;
pub mod params;
pub mod reply;
pub mod status;
pub mod stream;
pub mod units;
pub mod values;

pub use command::{
    BaudLevel, BroadcastEnable, BroadcastPos, BroadcastSpd, Command, Config, ConfigParam, Control,
    ControlOp, CtrlMode, Group, InfoBlock, Jog, JogDir, VendorCommand,
};
pub use error::ProtocolError;
pub use frame::{
    BroadcastFrame, BroadcastKind, CrcCoverage, Frame, FrameBytes, StandardFrame, FRAME_LEN,
};
pub use ids::{is_address, is_device_id, ALL_DEVICES, MAX_DEVICE_ID, MIN_DEVICE_ID};
pub use message::Message;
pub use reply::{Gains, Info01, Info02, Info04, Info05, Info06, Reply, ReplyBody};
pub use stream::{DecoderStats, StreamDecoder};
pub use units::FirmwareVersion;
