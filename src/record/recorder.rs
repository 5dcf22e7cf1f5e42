//! A recording in progress: a task that taps every bus (its snapshots for
//! joint states, its frame and setpoint taps, its events) and writes what
//! it hears to an [`McapFile`], closing a chunk every second, until it is
//! stopped, its duration is over, or a write fails.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;
use serde_json::json;
use tokio::sync::{broadcast, watch};

use crate::bus::handle::{BusEvent, Commanded, LoggedFrame};
use crate::bus::BusHandle;
use crate::protocol::frame_json::hex;
use crate::protocol::units;

use super::joint_states::{system_ns, JointStates, Labeler};
use super::mcap_file::{McapFile, McapFileError, SideEncoding, Topic, CHUNK_PERIOD};

/// How often the taps are drained (well under a poll round).
const DRAIN_EVERY: Duration = Duration::from_millis(5);

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
    stop: watch::Sender<bool>,
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
    /// Creates the file and starts recording `buses` (for `duration`, or
    /// until stopped).
    pub fn start(
        buses: Vec<BusHandle>,
        labeler: Labeler,
        path: PathBuf,
        duration: Option<Duration>,
        side: SideEncoding,
    ) -> Result<Self, McapFileError> {
        let names: Vec<String> = buses.iter().map(|b| b.name().to_owned()).collect();
        let file = McapFile::create(&path, &names, side)?;
        let tapped = buses
            .into_iter()
            .map(|bus| Tapped {
                snapshots: bus.watch(),
                frames: bus.shared().frame_tap.subscribe(),
                setpoints: bus.shared().setpoint_tap.subscribe(),
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
        let (stop, stop_rx) = watch::channel(false);
        let (done_tx, done) = watch::channel(false);
        let task_status = status.clone();
        tokio::spawn(async move {
            run(file, tapped, labeler, duration, stop_rx, &task_status).await;
            let _ = done_tx.send(true);
        });
        Ok(Self { stop, status, done })
    }

    pub fn status(&self) -> RecordStatus {
        lock(&self.status).clone()
    }

    /// Stops it and waits until the file is complete; its final status.
    pub async fn stop(&self) -> RecordStatus {
        let _ = self.stop.send(true);
        let mut done = self.done.clone();
        let _ = done.wait_for(|d| *d).await;
        self.status()
    }
}

async fn run(
    mut file: McapFile,
    mut buses: Vec<Tapped>,
    labeler: Labeler,
    duration: Option<Duration>,
    mut stop: watch::Receiver<bool>,
    status: &Mutex<RecordStatus>,
) {
    let started = Instant::now();
    let mut drain = tokio::time::interval(DRAIN_EVERY);
    drain.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_chunk = Instant::now();
    let mut lost = 0u64;
    let result: Result<(), McapFileError> = loop {
        tokio::select! {
            _ = stop.wait_for(|s| *s) => break Ok(()),
            _ = drain.tick() => {}
        }
        let mut wrote = Ok(());
        for b in &mut buses {
            wrote = wrote.and_then(|()| drain_bus(&mut file, b, &labeler, &mut lost));
        }
        if let Err(e) = wrote {
            break Err(e);
        }
        if last_chunk.elapsed() >= CHUNK_PERIOD {
            last_chunk = Instant::now();
            if let Err(e) = file.flush() {
                break Err(e);
            }
        }
        {
            let mut s = lock(status);
            s.messages = file.counts().clone();
            s.lost = lost;
        }
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break Ok(());
        }
    };
    // What the taps still hold, then the summary.
    let result = result.and_then(|()| {
        for b in &mut buses {
            drain_bus(&mut file, b, &labeler, &mut lost)?;
        }
        Ok(())
    });
    let counts = file.counts().clone();
    let result = match result {
        Ok(()) => file.finish(),
        Err(e) => {
            // Keep what was written: close the file as far as it goes.
            let _ = file.finish();
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
                            "pos_ref_raw": sp.pos_ref, "spd_ref_raw": sp.spd_ref})
                    })
                    .collect();
                let msg = json!({"seq": c.seq, "targets": targets});
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
