//! One MCAP file: its schemas and channels per bus, messages written in
//! zstd-compressed chunks of at most [`CHUNK_PERIOD`] (the recorder closes
//! a chunk that often, so a kill loses at most the last one), a summary
//! with indexes at the end.
//!
//! Channels, per bus `B`:
//! - `/B/joint_states`: `sensor_msgs/msg/JointState`, `ros2msg` schema, CDR;
//! - `/jointd/B/frames`: every frame on the wire, `{"dir", "wire_time_ns",
//!   "hex"}` (JSON, with its JSON schema);
//! - `/jointd/B/events`: device and bus events as the WebSocket tells them
//!   (JSON);
//! - `/jointd/B/setpoints`: targets as clients commanded them (JSON).
//!
//! [`SideEncoding::RosString`] writes the last three as
//! `std_msgs/msg/String` in CDR holding the same JSON text instead: every
//! channel then has one ROS serialization, which rosbag2 asks of a bag
//! it plays.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Duration;

use mcap::records::MessageHeader;
use mcap::{WriteOptions, Writer};
use thiserror::Error;

use super::cdr::{string_cdr, JOINT_STATE_MSG, STRING_MSG};

/// How long a chunk may collect messages before it is written out.
pub const CHUNK_PERIOD: Duration = Duration::from_secs(1);

#[derive(Debug, Error)]
pub enum McapFileError {
    #[error("recording {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("recording {path}: MCAP: {source}")]
    Mcap {
        path: String,
        source: mcap::McapError,
    },
}

/// What a bus's messages go to.
#[derive(Debug, Clone, Copy)]
pub struct BusChannels {
    pub joint_states: u16,
    pub frames: u16,
    pub events: u16,
    pub setpoints: u16,
}

/// Which channel of a bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Topic {
    JointStates,
    Frames,
    Events,
    Setpoints,
}

impl Topic {
    pub fn name(self, bus: &str) -> String {
        match self {
            Self::JointStates => format!("/{bus}/joint_states"),
            Self::Frames => format!("/jointd/{bus}/frames"),
            Self::Events => format!("/jointd/{bus}/events"),
            Self::Setpoints => format!("/jointd/{bus}/setpoints"),
        }
    }
}

const FRAME_SCHEMA: &str = r#"{"type":"object","title":"jointd wire frame","properties":{
"dir":{"type":"string","enum":["tx","rx"],"description":"tx: written by the host; rx: received from a device"},
"wire_time_ns":{"type":"integer","description":"Unix time the frame was on the wire, ns (the host's estimate)"},
"hex":{"type":"string","description":"The 20 bytes, hex, space-separated (jointd frame decode reads it)"}},
"required":["dir","wire_time_ns","hex"]}"#;
const EVENT_SCHEMA: &str = r#"{"type":"object","title":"jointd bus event","properties":{
"event":{"type":"string","description":"device_online, device_offline, fault, estop, device_reset, move_started, ... as docs/websocket.md lists them"},
"bus":{"type":"string"}},"required":["event"]}"#;
const SETPOINT_SCHEMA: &str = r#"{"type":"object","title":"jointd commanded targets","properties":{
"seq":{"type":"integer","description":"The write's sequence number in the bus's setpoint store"},
"targets":{"type":"array","items":{"type":"object","properties":{
"id":{"type":"integer"},"position_deg":{"type":"number","description":"In the joint's calibrated frame"},
"pos_ref_raw":{"type":"integer"},"spd_ref_raw":{"type":"integer"}}}}},"required":["seq","targets"]}"#;

/// How the frames, events and setpoints channels are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SideEncoding {
    /// JSON with a JSON schema (Foxglove shows the fields).
    #[default]
    Json,
    /// The same JSON text in a `std_msgs/msg/String`, CDR.
    RosString,
}

/// An MCAP file being written.
pub struct McapFile {
    path: String,
    writer: Writer<BufWriter<File>>,
    channels: BTreeMap<String, BusChannels>,
    sequence: u32,
    counts: BTreeMap<String, u64>,
    side: SideEncoding,
}

/// Names the file and what went into it.
impl std::fmt::Debug for McapFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("path", &self.path)
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

impl McapFile {
    /// Creates `path` (refusing to overwrite) with the channels of `buses`.
    pub fn create(
        path: &Path,
        buses: &[String],
        side: SideEncoding,
    ) -> Result<Self, McapFileError> {
        let shown = path.display().to_string();
        let io = |source| McapFileError::Io {
            path: shown.clone(),
            source,
        };
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(io)?;
        let options = WriteOptions::new()
            .profile("ros2")
            .library(concat!("jointd ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(4 << 20));
        let mcap = |source| McapFileError::Mcap {
            path: shown.clone(),
            source,
        };
        let mut writer = options.create(BufWriter::new(file)).map_err(mcap)?;
        let joint_state = writer
            .add_schema(
                "sensor_msgs/msg/JointState",
                "ros2msg",
                JOINT_STATE_MSG.as_bytes(),
            )
            .map_err(mcap)?;
        let mut json_schema = |name: &str, text: &str| match side {
            SideEncoding::Json => writer.add_schema(name, "jsonschema", text.as_bytes()),
            SideEncoding::RosString => {
                writer.add_schema("std_msgs/msg/String", "ros2msg", STRING_MSG.as_bytes())
            }
        };
        let frame = json_schema("jointd/Frame", FRAME_SCHEMA).map_err(mcap)?;
        let event = json_schema("jointd/BusEvent", EVENT_SCHEMA).map_err(mcap)?;
        let setpoint = json_schema("jointd/Setpoints", SETPOINT_SCHEMA).map_err(mcap)?;
        let side_encoding = match side {
            SideEncoding::Json => "json",
            SideEncoding::RosString => "cdr",
        };
        let none = BTreeMap::new();
        let mut channels = BTreeMap::new();
        for bus in buses {
            let mut add = |schema, topic: Topic, encoding| {
                writer.add_channel(schema, &topic.name(bus), encoding, &none)
            };
            let ch = BusChannels {
                joint_states: add(joint_state, Topic::JointStates, "cdr").map_err(mcap)?,
                frames: add(frame, Topic::Frames, side_encoding).map_err(mcap)?,
                events: add(event, Topic::Events, side_encoding).map_err(mcap)?,
                setpoints: add(setpoint, Topic::Setpoints, side_encoding).map_err(mcap)?,
            };
            channels.insert(bus.clone(), ch);
        }
        Ok(Self {
            path: shown,
            writer,
            channels,
            sequence: 0,
            counts: BTreeMap::new(),
            side,
        })
    }

    fn mcap_err(&self, source: mcap::McapError) -> McapFileError {
        McapFileError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// Writes one message of `bus`'s `topic` logged at `log_ns` (Unix ns).
    pub fn write(
        &mut self,
        bus: &str,
        topic: Topic,
        log_ns: u64,
        data: &[u8],
    ) -> Result<(), McapFileError> {
        let Some(ch) = self.channels.get(bus) else {
            return Ok(());
        };
        let channel_id = match topic {
            Topic::JointStates => ch.joint_states,
            Topic::Frames => ch.frames,
            Topic::Events => ch.events,
            Topic::Setpoints => ch.setpoints,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        let wrapped;
        let data = match (topic, self.side) {
            (Topic::JointStates, _) | (_, SideEncoding::Json) => data,
            (_, SideEncoding::RosString) => {
                wrapped = string_cdr(&String::from_utf8_lossy(data));
                &wrapped
            }
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_err(e))?;
        *self.counts.entry(topic.name(bus)).or_default() += 1;
        Ok(())
    }

    /// Messages written so far, by topic.
    pub fn counts(&self) -> &BTreeMap<String, u64> {
        &self.counts
    }

    /// Closes the current chunk and hands it to the file.
    pub fn flush(&mut self) -> Result<(), McapFileError> {
        self.writer.flush().map_err(|e| self.mcap_err(e))
    }

    /// Writes the summary and the footer, and flushes the file to the disk.
    pub fn finish(mut self) -> Result<(), McapFileError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let path = self.path.clone();
        let mut out = self.writer.into_inner();
        out.flush()
            .and_then(|()| out.get_ref().sync_all())
            .map_err(|source| McapFileError::Io { path, source })
    }
}
