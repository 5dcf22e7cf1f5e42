//! A recording in progress: a thread that taps every bus (its snapshots for
//! joint states, its frame and setpoint taps, its events) and writes what
//! it hears to an [`McapFile`], closing a chunk every second, until it is
//! stopped, its duration is over, or a write fails.
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
use serde_json::json;
use tokio::sync::{broadcast, watch};

use crate::bus::handle::{BusEvent, Commanded, LoggedFrame};
use crate::bus::{BusHandle, BusSnapshot};
use crate::protocol::frame_json::hex;
use crate::protocol::units;
use crate::protocol::CtrlMode;

use super::joint_states::{system_ns, JointStates, Labeler};
use super::mcap_file::{McapFile, McapFileError, SideEncoding, Topic, CHUNK_PERIOD};
use super::metadata::{self, JointInfo};

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

/// One bus as the recording hears it.
struct Tapped {
    bus: BusHandle,
    snapshots: watch::Receiver<Arc<crate::bus::BusSnapshot>>,
    frames: broadcast::Receiver<LoggedFrame>,
    setpoints: broadcast::Receiver<Commanded>,
    events: broadcast::Receiver<BusEvent>,
    joint_states: JointStates,
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
        let tapped = buses
            .into_iter()
            .map(|bus| Tapped {
                snapshots: bus.watch(),
                frames: bus.shared().frame_tap.subscribe(),
                setpoints: bus.shared().setpoints.subscribe(),
                events: bus.events(),
                joint_states: JointStates::new(bus.name(), labeler.clone()),
                bus,
            })
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
                lower_priority();
                run(file, tapped, labeler, duration, &task_stop, &task_status);
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

/// Lowers the calling thread's priority (Linux: nice applies per thread).
fn lower_priority() {
    // SAFETY: gettid and setpriority take integers and touch no memory; a
    // tid names the calling thread for PRIO_PROCESS on Linux.
    let rc = unsafe {
        let tid = libc::gettid();
        libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, RECORDER_NICE)
    };
    if rc != 0 {
        tracing::debug!(
            "recording thread: setpriority failed: {}",
            std::io::Error::last_os_error()
        );
    }
}

/// The recording's loop: drain, chunk, until stopped, over or failed.
fn record(
    file: &mut McapFile,
    buses: &mut [Tapped],
    labeler: &Labeler,
    duration: Option<Duration>,
    stop: &AtomicBool,
    status: &Mutex<RecordStatus>,
    lost: &mut u64,
) -> Result<(), McapFileError> {
    let started = Instant::now();
    let mut last_chunk = Instant::now();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(DRAIN_EVERY);
        for b in buses.iter_mut() {
            drain_bus(file, b, labeler, lost)?;
        }
        if last_chunk.elapsed() >= CHUNK_PERIOD {
            last_chunk = Instant::now();
            file.flush()?;
        }
        {
            let mut s = lock(status);
            s.messages = file.counts().clone();
            s.lost = *lost;
        }
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
    }
    // What the taps still hold, then the summary.
    for b in buses.iter_mut() {
        drain_bus(file, b, labeler, lost)?;
    }
    Ok(())
}

fn run(
    mut file: McapFile,
    mut buses: Vec<Tapped>,
    labeler: Labeler,
    duration: Option<Duration>,
    stop: &AtomicBool,
    status: &Mutex<RecordStatus>,
) {
    let mut lost = 0u64;
    let result = record(
        &mut file, &mut buses, &labeler, duration, stop, status, &mut lost,
    );
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

/// Everything one bus's taps hold now, and a joint state if a round
/// completed.
fn drain_bus(
    file: &mut McapFile,
    b: &mut Tapped,
    labeler: &Labeler,
    lost: &mut u64,
) -> Result<(), McapFileError> {
    let bus = b.bus.name().to_owned();
    // Which joints are online: a round is complete when each has answered.
    let snap = b.snapshots.borrow_and_update().clone();
    loop {
        match b.frames.try_recv() {
            Ok(f) => {
                let ns = system_ns(f.at);
                let msg = json!({"dir": if f.tx { "tx" } else { "rx" }, "wire_time_ns": ns, "hex": hex(&f.bytes)});
                file.write(&bus, Topic::Frames, ns, msg.to_string().as_bytes())?;
                b.joint_states.on_frame(&bus, &f);
                if let Some(state) = b.joint_states.next(&[&snap]) {
                    file.write(&bus, Topic::JointStates, state.stamp_ns, &state.to_cdr())?;
                }
            }
            Err(broadcast::error::TryRecvError::Lagged(n)) => *lost += n,
            Err(_) => break,
        }
    }
    loop {
        match b.setpoints.try_recv() {
            Ok(c) => {
                let targets: Vec<_> = c
                    .targets
                    .iter()
                    .map(|(id, sp)| {
                        let (_, cal) = labeler(&bus, *id);
                        json!({"id": id, "position_deg": cal.to_joint(units::angle_deg(sp.pos_ref)),
                            "speed_dps": target_speed_dps(&snap, *id, sp.spd_ref, cal.sign()),
                            "pos_ref_raw": sp.pos_ref, "spd_ref_raw": sp.spd_ref})
                    })
                    .collect();
                let mut msg = serde_json::to_value(c.source).unwrap_or_else(|_| json!({}));
                msg["seq"] = json!(c.seq);
                msg["targets"] = json!(targets);
                let ns = system_ns(c.at);
                file.write(&bus, Topic::Setpoints, ns, msg.to_string().as_bytes())?;
            }
            Err(broadcast::error::TryRecvError::Lagged(n)) => *lost += n,
            Err(_) => break,
        }
    }
    loop {
        match b.events.try_recv() {
            Ok(e) => {
                let text = serde_json::to_string(&e).unwrap_or_default();
                let ns = system_ns(SystemTime::now());
                file.write(&bus, Topic::Events, ns, text.as_bytes())?;
            }
            Err(broadcast::error::TryRecvError::Lagged(n)) => *lost += n,
            Err(_) => break,
        }
    }
    Ok(())
}

/// A target's speed as the REST and WebSocket views give it: output °/s,
/// the limit in position mode, signed (in the joint's frame) in speed mode.
fn target_speed_dps(snap: &BusSnapshot, id: u8, spd_ref: i16, sign: f64) -> f64 {
    let dev = snap.devices.get(&id);
    let fw = dev.map(|d| d.firmware_version()).unwrap_or_default();
    let dps = (units::speed_dps(spd_ref, fw) * 1000.0).round() / 1000.0;
    if dev.and_then(|d| d.mode) == Some(CtrlMode::Speed) {
        sign * dps
    } else {
        dps
    }
}
