//! One MCAP file: its schemas and channels per bus, messages written in
//! zstd-compressed chunks of at most [`CHUNK_PERIOD`] (the recorder closes
//! a chunk that often, so a kill loses at most the last one), a summary
//! with indexes at the end.
//!
//! Channels, per bus `B`:
//! - `/B/joint_states`: `sensor_msgs/msg/JointState`, `ros2msg` schema, CDR;
//! - `/jointd/B/frames`: every frame on the wire, `{"dir", "wire_time_ns",
//!   "hex"}` (JSON, with its JSON schema: [`super::schemas`] has them all);
//! - `/jointd/B/events`: device and bus events as the WebSocket tells them
//!   (JSON);
//! - `/jointd/B/setpoints`: every target the bus's joints were given, with
//!   who gave it (a client, a stream, a move per control cycle, a homing
//!   step, a hold) (JSON).
//!
//! [`SideEncoding::RosString`] writes the last three as
//! `std_msgs/msg/String` in CDR holding the same JSON text instead: every
//! channel then has one ROS serialization, which rosbag2 asks of a bag
//! it plays.
//!
//! The header's profile is `ros2` only on such a file: the MCAP `ros2`
//! profile asks that every channel be CDR with a `ros2msg` schema and carry
//! `offered_qos_profiles` metadata. A file with JSON channels says no
//! profile (`""`). Every CDR channel carries [`OFFERED_QOS_PROFILES`].

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use mcap::records::MessageHeader;
use mcap::{WriteOptions, Writer};
use thiserror::Error;

use super::channels::add_channels;
use super::sink::{Failure, Sink};
use crate::rosmsg::string_cdr;

pub use super::channels::{BusChannels, SideEncoding, Topic, OFFERED_QOS_PROFILES};

/// How long a chunk may collect messages before it is written out.
pub const CHUNK_PERIOD: Duration = Duration::from_secs(1);

/// Why a recording's file could not be made or written.
#[derive(Debug, Error)]
pub enum McapFileError {
    #[error("recording {path}: cannot create the file: {source}")]
    Create {
        path: String,
        source: std::io::Error,
    },
    #[error("recording {path}: writing the file failed: {source}")]
    Write {
        path: String,
        source: std::io::Error,
    },
    #[error("recording {path}: MCAP: {source}")]
    Mcap {
        path: String,
        source: mcap::McapError,
    },
    #[error("recording {path}: the file was removed from the disk while recording")]
    Removed { path: String },
    #[error("recording {path}: cannot start its thread: {source}")]
    Thread {
        path: String,
        source: std::io::Error,
    },
}

impl McapFileError {
    /// The disk (or the user's quota, or the file size limit) is full: the
    /// file cannot take more, whatever is retried.
    pub fn storage_full(&self) -> bool {
        let io = match self {
            Self::Create { source, .. } | Self::Write { source, .. } => source,
            _ => return false,
        };
        matches!(
            io.raw_os_error(),
            Some(libc::ENOSPC | libc::EDQUOT | libc::EFBIG)
        )
    }
}

/// An MCAP file being written (over `W`: the file, or a test's stream).
pub struct McapFile<W: Write = BufWriter<File>> {
    path: String,
    writer: Writer<Sink<W>>,
    /// The first I/O error under the writer (see [`super::sink`]).
    failure: Failure,
    /// The file itself (a second handle), to see it removed and to sync it.
    file: Option<File>,
    channels: BTreeMap<String, BusChannels>,
    sequence: u32,
    counts: BTreeMap<String, u64>,
    /// Messages written, as of the last chunk that reached the file.
    on_disk: u64,
    side: SideEncoding,
}

/// Names the file and what went into it.
impl<W: Write> std::fmt::Debug for McapFile<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("path", &self.path)
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

impl McapFile {
    /// Creates `path` (refusing to overwrite) with the channels of `buses`,
    /// and writes its header, schemas and channels through to the file, so
    /// a full disk is known here. On failure no file is left.
    pub fn create(
        path: &Path,
        buses: &[String],
        side: SideEncoding,
    ) -> Result<Self, McapFileError> {
        let shown = path.display().to_string();
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|source| McapFileError::Create {
                path: shown.clone(),
                source,
            })?;
        let watch = file.try_clone().ok();
        let made = Self::over(BufWriter::new(file), &shown, buses, side).and_then(|mut f| {
            f.file = watch;
            f.flush().map(|()| f)
        });
        made.map_err(|e| {
            // Ours (create_new): nothing of it is worth keeping.
            let _ = std::fs::remove_file(path);
            match e {
                McapFileError::Write { path, source } => McapFileError::Create { path, source },
                other => other,
            }
        })
    }
}

impl<W: Write> McapFile<W> {
    /// An MCAP stream over `out`, named `path` in errors.
    pub fn over(
        out: W,
        path: &str,
        buses: &[String],
        side: SideEncoding,
    ) -> Result<Self, McapFileError> {
        let (sink, failure) = Sink::new(out);
        let options = WriteOptions::new()
            .profile(side.profile())
            .library(concat!("jointd ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(4 << 20))
            // Chunks built in memory and written whole: the sink cannot seek.
            .disable_seeking(true);
        let mcap = |source| McapFileError::Mcap {
            path: path.to_owned(),
            source,
        };
        let mut writer = options.create(sink).map_err(mcap)?;
        let channels = add_channels(&mut writer, buses, side).map_err(mcap)?;
        let made = Self {
            path: path.to_owned(),
            writer,
            failure,
            file: None,
            channels,
            sequence: 0,
            counts: BTreeMap::new(),
            on_disk: 0,
            side,
        };
        made.check()?;
        Ok(made)
    }

    /// The path, as errors name it.
    pub fn path(&self) -> &str {
        &self.path
    }

    fn mcap_err(&self, source: mcap::McapError) -> McapFileError {
        McapFileError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// The write error the sink kept, if any.
    fn check(&self) -> Result<(), McapFileError> {
        match self.failure.get() {
            Some(source) => Err(McapFileError::Write {
                path: self.path.clone(),
                source,
            }),
            None => Ok(()),
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
        self.check()?;
        *self.counts.entry(topic.name(bus)).or_default() += 1;
        Ok(())
    }

    /// Writes a Metadata record `name` (before the first message: it closes
    /// the chunk being built).
    pub fn write_metadata(
        &mut self,
        name: &str,
        metadata: BTreeMap<String, String>,
    ) -> Result<(), McapFileError> {
        let record = mcap::records::Metadata {
            name: name.to_owned(),
            metadata,
        };
        self.writer
            .write_metadata(&record)
            .map_err(|e| self.mcap_err(e))?;
        self.check()
    }

    /// Messages written so far, by topic.
    pub fn counts(&self) -> &BTreeMap<String, u64> {
        &self.counts
    }

    /// Closes the current chunk and hands it to the file; fails when the
    /// file could not take it or was removed from the disk.
    pub fn flush(&mut self) -> Result<(), McapFileError> {
        self.writer.flush().map_err(|e| self.mcap_err(e))?;
        self.check()?;
        if self.removed() {
            return Err(McapFileError::Removed {
                path: self.path.clone(),
            });
        }
        self.on_disk = self.counts.values().sum();
        Ok(())
    }

    /// True when the file has no name left on the disk (writes to it still
    /// succeed: they go nowhere anyone can read).
    fn removed(&self) -> bool {
        self.file
            .as_ref()
            .and_then(|f| f.metadata().ok())
            .is_some_and(|m| m.nlink() == 0)
    }

    /// Writes the summary and the footer, and flushes the file to the disk.
    pub fn finish(mut self) -> Result<(), McapFileError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        self.check()?;
        let (file, path) = (self.file.take(), self.path);
        let mut sink = self.writer.into_inner();
        sink.flush_inner();
        let synced = match (self.failure.get(), file) {
            (Some(e), _) => Err(e),
            (None, Some(f)) => f.sync_all(),
            (None, None) => Ok(()),
        };
        synced.map_err(|source| McapFileError::Write { path, source })
    }

    /// Closes a file whose recording failed: what reached the disk stays
    /// (chunks are readable without the summary), unless no message did,
    /// then the file is removed, if its path still names it.
    pub fn close_failed(mut self) {
        let _ = self.writer.finish();
        let file = self.file.take();
        drop(self.writer.into_inner());
        if self.on_disk > 0 {
            return;
        }
        let path = PathBuf::from(&self.path);
        let ours = match (file.and_then(|f| f.metadata().ok()), path.metadata()) {
            (Some(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        };
        if ours {
            let _ = std::fs::remove_file(&path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn buses() -> Vec<String> {
        vec!["sim0".to_owned()]
    }

    /// `/dev/full`: every write the kernel fails with ENOSPC, as a full disk.
    fn dev_full() -> BufWriter<File> {
        BufWriter::new(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .expect("/dev/full"),
        )
    }

    #[test]
    fn a_finished_file_reads_back_whole_with_its_summary() {
        let dir = std::env::temp_dir().join(format!("jointd-mcap-ok-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ok.mcap");
        let _ = std::fs::remove_file(&path);
        let mut file = McapFile::create(&path, &buses(), SideEncoding::Json).unwrap();
        for chunk in 0..3u64 {
            for i in 0..10 {
                let ns = chunk * 1000 + i;
                file.write("sim0", Topic::Events, ns, b"{\"event\":\"x\"}")
                    .unwrap();
            }
            file.flush().unwrap();
        }
        file.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let read: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(read.len(), 30);
        assert!(read
            .iter()
            .all(|m| m.channel.topic == "/jointd/sim0/events"));
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        assert_eq!(summary.stats.map(|s| s.message_count), Some(30));
        assert!(
            summary.chunk_indexes.len() >= 3,
            "{}",
            summary.chunk_indexes.len()
        );
        let _ = std::fs::remove_dir_all(dir);
    }

    /// The header's profile and every channel's encoding, schema encoding
    /// and QoS metadata, of a file written with `side`.
    fn profile_and_channels(side: SideEncoding) -> (String, Vec<(String, String, bool)>) {
        let mut file = McapFile::over(Vec::new(), "mem.mcap", &buses(), side).unwrap();
        file.write("sim0", Topic::Events, 1, b"{\"event\":\"x\"}")
            .unwrap();
        file.writer.finish().unwrap();
        let bytes = file.writer.into_inner().get_ref().clone();
        let profile = mcap::read::LinearReader::new(&bytes)
            .unwrap()
            .find_map(|r| match r {
                Ok(mcap::records::Record::Header(h)) => Some(h.profile),
                _ => None,
            })
            .expect("a header");
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let channels = summary
            .channels
            .values()
            .map(|c| {
                let schema = c.schema.as_ref().map(|s| s.encoding.clone());
                let qos = c.metadata.get("offered_qos_profiles").map(String::as_str)
                    == Some(OFFERED_QOS_PROFILES);
                (c.message_encoding.clone(), schema.unwrap_or_default(), qos)
            })
            .collect();
        (profile, channels)
    }

    #[test]
    fn the_ros2_profile_only_on_a_file_of_cdr_channels_each_with_its_qos() {
        let (profile, channels) = profile_and_channels(SideEncoding::Json);
        assert_eq!(profile, "", "JSON channels: no profile");
        assert_eq!(channels.len(), 4);
        for (encoding, schema, qos) in &channels {
            let cdr = encoding == "cdr";
            assert_eq!(
                qos, &cdr,
                "{encoding}/{schema}: QoS on the CDR channel only"
            );
        }
        let (profile, channels) = profile_and_channels(SideEncoding::RosString);
        assert_eq!(profile, "ros2");
        assert_eq!(channels.len(), 4);
        assert!(
            channels
                .iter()
                .all(|(e, s, qos)| e == "cdr" && s == "ros2msg" && *qos),
            "{channels:?}"
        );
    }

    #[test]
    fn a_full_disk_is_an_error_not_a_panic() {
        let mut file = McapFile::over(dev_full(), "full.mcap", &buses(), SideEncoding::Json)
            .expect("nothing reached the disk yet");
        file.write("sim0", Topic::Events, 1, b"{\"event\":\"x\"}")
            .expect("buffered");
        let err = file.flush().expect_err("the chunk reached the disk");
        assert!(err.storage_full(), "{err}");
        assert!(err.to_string().contains("No space left"), "{err}");
        // Later calls fail the same way, and closing it panics neither.
        assert!(file.write("sim0", Topic::Events, 2, b"{}").is_err());
        file.close_failed();
    }

    #[test]
    fn a_disk_full_before_the_header_fails_at_once() {
        let unbuffered = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .expect("/dev/full");
        let err = McapFile::over(unbuffered, "full.mcap", &buses(), SideEncoding::Json)
            .expect_err("the header could not be written");
        assert!(err.storage_full(), "{err}");
    }

    #[test]
    fn a_file_removed_from_the_disk_is_said_at_the_next_chunk() {
        let dir = std::env::temp_dir().join(format!("jointd-mcap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ok.mcap");
        let _ = std::fs::remove_file(&path);
        let mut file = McapFile::create(&path, &buses(), SideEncoding::Json).unwrap();
        file.write("sim0", Topic::Events, 1, b"{\"event\":\"x\"}")
            .unwrap();
        file.flush().unwrap();
        // Its name goes: the next chunk says so.
        std::fs::remove_file(&path).unwrap();
        file.write("sim0", Topic::Events, 2, b"{}").unwrap();
        let err = file.flush().expect_err("removed");
        assert!(matches!(err, McapFileError::Removed { .. }), "{err}");
        assert!(!err.storage_full());
        file.close_failed();
        assert!(!path.exists(), "close_failed must not make a new file");
        let _ = std::fs::remove_dir_all(dir);
    }
}
