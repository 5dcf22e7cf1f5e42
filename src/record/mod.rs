//! Recordings: what the joints did, in an MCAP file that
//! Foxglove and `ros2 bag play` (storage plugin mcap) open as is.
//!
//! - [`joint_states`]: a `JointState` per poll round from a bus's snapshots;
//! - [`channels`]: a recording's channels per bus, their schemas and QoS;
//! - [`mcap_file`]: the file: chunks, summary;
//! - [`metadata`]: its Metadata record `jointd` (version, joints);
//! - [`schemas`]: the JSON channels' schemas, every field typed;
//! - [`sink`]: the stream under the MCAP writer, which keeps I/O errors
//!   from it (the writer panics after one) for the file to report;
//! - [`tap`]: a bus's taps turned into the channels' messages (topic, log
//!   time, bytes), for the recorder and the live Foxglove view alike;
//! - [`recorder`]: the thread that taps the buses and writes;
//! - [`client`]: `jointd record`, which asks a running daemon for one.

pub mod channels;
pub mod client;
pub mod joint_states;
pub mod mcap_file;
pub mod metadata;
pub mod recorder;
pub mod schemas;
pub mod sink;
pub mod tap;

pub use recorder::{RecordState, RecordStatus, Recorder};
