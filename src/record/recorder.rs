//! A recording in progress: a thread that taps every bus (its snapshots for
//! joint states, its frame and setpoint taps, its events) and writes what
//! it hears ([`BusTap`] makes the messages) to an [`McapFile`], closing a
//! chunk every second, until it is stopped, its duration is over, or a
//! write fails.
//!
//! A thread of its own, not a task: encoding every frame, compressing the
//! chunks and writing the file are CPU and disk work that would hold an
//! async worker, and with it the requests (an e-stop among them) queued
//! behind it. The thread runs at a lower priority than the daemon's others,
//! so a busy host slows the recording, never the API or the buses.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;
use tokio::sync::watch;

use crate::bus::BusHandle;

use super::joint_states::{system_ns, Labeler};
use super::mcap_file::{McapFile, McapFileError, SideEncoding, CHUNK_PERIOD};
use super::metadata::{self, JointInfo};
use super::tap::{BusTap, Taps};

/// How often the taps are drained (well under a poll round).
const DRAIN_EVERY: Duration = Duration::from_millis(5);
/// The recording thread's nice value: below the API's and the buses' threads.
const RECORDER_NICE: libc::c_int = 10;

/// Where a recording stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordState {
    Recording,
    /// Stopped (asked, or its duration over): the file is complete.
    Finished,
    /// A write failed: the file holds what was written before.
    Failed,
}

/// A recording's progress, shared with whoever asks.
#[derive(Debug, Clone, Serialize)]
pub struct RecordStatus {
    pub state: RecordState,
    pub path: PathBuf,
    pub started_ns: u64,
    pub ended_ns: Option<u64>,
    /// Messages written, by topic.
    pub messages: BTreeMap<String, u64>,
    /// Frames or commanded targets the recording fell too far behind to
    /// keep (the taps hold seconds of them: none on a healthy host).
    pub lost: u64,
    pub error: Option<String>,
}

/// A running recording: stop it, read its status.
pub struct Recorder {
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<RecordStatus>>,
    done: watch::Receiver<bool>,
}

/// Its status.
impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("status", &self.status())
            .finish_non_exhaustive()
    }
}

/// A recording nobody holds any more is stopped (its file completed).
impl Drop for Recorder {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

fn lock(m: &Mutex<RecordStatus>) -> MutexGuard<'_, RecordStatus> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Recorder {
    /// Creates the file with its metadata record (`joints`: what the
    /// recording knows of them) and starts recording `buses` (for
    /// `duration`, or until stopped).
    pub fn start(
        buses: Vec<BusHandle>,
        labeler: Labeler,
        joints: &[JointInfo],
        path: PathBuf,
        duration: Option<Duration>,
        side: SideEncoding,
    ) -> Result<Self, McapFileError> {
        let names: Vec<String> = buses.iter().map(|b| b.name().to_owned()).collect();
        let mut file = McapFile::create(&path, &names, side)?;
        let written = file
            .write_metadata(metadata::NAME, metadata::record(joints))
            .and_then(|()| file.flush());
        if let Err(e) = written {
            file.close_failed();
            return Err(e);
        }
        let tapped: Vec<BusTap> = buses
            .iter()
            .map(|bus| BusTap::new(bus.name(), Taps::of(bus), labeler.clone()))
            .collect();
        let status = Arc::new(Mutex::new(RecordStatus {
            state: RecordState::Recording,
            path,
            started_ns: system_ns(SystemTime::now()),
            ended_ns: None,
            messages: BTreeMap::new(),
            lost: 0,
            error: None,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let (done_tx, done) = watch::channel(false);
        let (task_status, task_stop) = (status.clone(), stop.clone());
        let spawned = std::thread::Builder::new()
            .name("recording".into())
            .spawn(move || {
                crate::rt::lower_priority(RECORDER_NICE);
                run(file, tapped, duration, &task_stop, &task_status);
                let _ = done_tx.send(true);
            });
        if let Err(source) = spawned {
            return Err(McapFileError::Thread {
                path: lock(&status).path.display().to_string(),
                source,
            });
        }
        Ok(Self { stop, status, done })
    }

    pub fn status(&self) -> RecordStatus {
        lock(&self.status).clone()
    }

    /// Stops it and waits until the file is complete; its final status.
    pub async fn stop(&self) -> RecordStatus {
        self.stop.store(true, Ordering::Release);
        let mut done = self.done.clone();
        let _ = done.wait_for(|d| *d).await;
        self.status()
    }
}

/// The recording's loop: drain, chunk, until stopped, over or failed.
fn record(
    file: &mut McapFile,
    buses: &mut [BusTap],
    duration: Option<Duration>,
    stop: &AtomicBool,
    status: &Mutex<RecordStatus>,
) -> Result<(), McapFileError> {
    let started = Instant::now();
    let mut last_chunk = Instant::now();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(DRAIN_EVERY);
        for b in buses.iter_mut() {
            drain_bus(file, b)?;
        }
        if last_chunk.elapsed() >= CHUNK_PERIOD {
            last_chunk = Instant::now();
            file.flush()?;
        }
        {
            let mut s = lock(status);
            s.messages = file.counts().clone();
            s.lost = lost_in(buses);
        }
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
    }
    // What the taps still hold, then the summary.
    for b in buses.iter_mut() {
        drain_bus(file, b)?;
    }
    Ok(())
}

fn run(
    mut file: McapFile,
    mut buses: Vec<BusTap>,
    duration: Option<Duration>,
    stop: &AtomicBool,
    status: &Mutex<RecordStatus>,
) {
    let result = record(&mut file, &mut buses, duration, stop, status);
    let lost = lost_in(&buses);
    let counts = file.counts().clone();
    let result = match result {
        Ok(()) => file.finish(),
        Err(e) => {
            file.close_failed();
            Err(e)
        }
    };
    let mut s = lock(status);
    s.messages = counts;
    s.lost = lost;
    s.ended_ns = Some(system_ns(SystemTime::now()));
    match result {
        Ok(()) => {
            s.state = RecordState::Finished;
            tracing::info!(path = %s.path.display(), messages = ?s.messages, lost, "recording finished");
        }
        Err(e) => {
            tracing::error!(path = %s.path.display(), error = %e, "recording failed");
            s.state = RecordState::Failed;
            s.error = Some(e.to_string());
        }
    }
}

/// Everything one bus's taps hold now, written to the file.
fn drain_bus(file: &mut McapFile, b: &mut BusTap) -> Result<(), McapFileError> {
    let bus = b.bus().to_owned();
    b.drain(
        |_| true,
        |topic, ns, data| file.write(&bus, topic, ns, data),
    )
}

/// What the taps of every bus fell too far behind to keep.
fn lost_in(buses: &[BusTap]) -> u64 {
    buses.iter().map(BusTap::lost).sum()
}
