//! Recordings made through the API (`POST /api/v1/recordings`): started,
//! listed, stopped, downloaded. The files go to the recordings directory
//! (`state_dir/recordings`, else a directory under the system's temporary
//! one); a std `Mutex` guards the book, never held across an `.await`.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use utoipa::ToSchema;

use crate::bus::BusHandle;
use crate::control::books::recordings::{view, Book, Entry, RecordingView};
use crate::control::error::{ControlError, ControlResult};
use crate::control::state::Control;
use crate::record::joint_states::Labeler;
use crate::record::mcap_file::{McapFileError, SideEncoding};
use crate::record::metadata::JointInfo;
use crate::record::{RecordState, Recorder};

/// Recordings running at once, at most.
const MAX_RUNNING: usize = 4;
/// The longest recording asked with a duration, s (a day).
const MAX_DURATION_S: f64 = 86_400.0;

/// A recording to start.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"duration_s": 5.0}))]
pub(crate) struct RecordingRequest {
    /// Stop by itself after this long, s (0 < d ≤ 86400); absent: until
    /// `DELETE`.
    #[schema(example = 5.0, exclusive_minimum = 0.0, maximum = 86400.0)]
    pub duration_s: Option<f64>,
    /// The buses to record (default: all).
    #[schema(example = json!(["sim0"]))]
    pub buses: Option<Vec<String>>,
    /// Write frames, events and setpoints as `std_msgs/msg/String` (CDR,
    /// the same JSON text) instead of JSON, so every channel has one ROS
    /// serialization, as `ros2 bag play` asks (default false).
    #[schema(example = false)]
    pub bag_compatible: Option<bool>,
}

/// The buses a request names, each known and named once; all without a list.
fn requested_buses(state: &Arc<Control>, req: &RecordingRequest) -> ControlResult<Vec<BusHandle>> {
    let Some(names) = &req.buses else {
        return Ok(state.buses().cloned().collect());
    };
    if names.is_empty() {
        return Err(ControlError::invalid("buses", "buses is empty"));
    }
    let mut out: Vec<BusHandle> = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        if let Some(first) = names[..i].iter().position(|n| n == name) {
            return Err(ControlError::invalid(
                &format!("buses[{i}]"),
                format!("bus `{name}` appears twice in buses (buses[{first}] and buses[{i}])"),
            ));
        }
        out.push(state.bus(name)?.clone());
    }
    Ok(out)
}

/// Every joint of `buses` the daemon knows (its devices, and the hands'
/// joints on them), as the recording's metadata tells them.
fn joints_of(state: &Arc<Control>, buses: &[BusHandle], labeler: &Labeler) -> Vec<JointInfo> {
    let hand_joints: Vec<(String, u8, String)> = state
        .hands()
        .map(|store| {
            store
                .hands()
                .iter()
                .flat_map(|h| {
                    h.joints
                        .iter()
                        .map(|j| (j.bus.clone(), j.id, h.name.clone()))
                })
                .collect()
        })
        .unwrap_or_default();
    let mut out = Vec::new();
    for bus in buses {
        let snap = bus.snapshot();
        let mut ids: BTreeSet<u8> = snap.devices.keys().copied().collect();
        ids.extend(
            hand_joints
                .iter()
                .filter(|(b, _, _)| b == bus.name())
                .map(|(_, id, _)| *id),
        );
        for id in ids {
            let dev = snap.devices.get(&id);
            let (name, cal) = labeler(bus.name(), id);
            out.push(JointInfo {
                bus: bus.name().to_owned(),
                id,
                name,
                hand: hand_joints
                    .iter()
                    .find(|(b, i, _)| b == bus.name() && *i == id)
                    .map(|(_, _, hand)| hand.clone()),
                online: dev.is_some_and(|d| d.online),
                firmware: dev
                    .and_then(|d| d.info01.as_ref())
                    .map(|(info, _)| info.firmware().dotted()),
                protocol_revision: dev
                    .and_then(|d| d.firmware.as_ref())
                    .map(|f| f.revision.as_str().to_owned()),
                calibration: (&cal).into(),
            });
        }
    }
    out
}

/// Checks the request, takes a place among the [`MAX_RUNNING`], creates
/// the file (on a blocking thread: a slow or full disk holds no async
/// worker) and starts the recording. A file that cannot be made is a
/// problem naming why (507 when the disk is full), with no file left.
pub(crate) async fn start(
    state: &Arc<Control>,
    req: &RecordingRequest,
) -> ControlResult<RecordingView> {
    check_duration(req.duration_s)?;
    let buses = requested_buses(state, req)?;
    let place = Place::take(state)?;
    let id = place.id;
    let names: Vec<String> = buses.iter().map(|b| b.name().to_owned()).collect();
    let (dir, labeler) = (state.recordings_dir(), state.joint_labeler());
    let joints = joints_of(state, &buses, &labeler);
    let duration = req.duration_s.map(Duration::from_secs_f64);
    let side = if req.bag_compatible.unwrap_or(false) {
        SideEncoding::RosString
    } else {
        SideEncoding::Json
    };
    let made = tokio::task::spawn_blocking(move || {
        std::fs::create_dir_all(&dir).map_err(|source| McapFileError::Create {
            path: dir.display().to_string(),
            source,
        })?;
        let started_s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let path: PathBuf = dir.join(format!("rec-{id}-{started_s}.mcap"));
        Recorder::start(buses, labeler, &joints, path, duration, side)
    })
    .await;
    let mut book = state.recordings().lock();
    place.give_back(&mut book);
    let recorder = match made {
        Ok(Ok(recorder)) => recorder,
        Ok(Err(e)) => {
            tracing::warn!(recording = id, error = %e, "recording not started");
            return Err(ControlError::recording_unwritable(&e));
        }
        Err(_) => {
            return Err(ControlError::internal(
                "the recording's file could not be made (its task ended)",
            ))
        }
    };
    let entry = Entry {
        recorder: Arc::new(recorder),
        buses: names,
        duration_s: req.duration_s,
    };
    let v = view(id, &entry, &entry.recorder.status());
    tracing::info!(recording = id, file = %v.file, buses = ?v.buses, duration_s = ?v.duration_s, "recording started");
    book.entries.insert(id, entry);
    Ok(v)
}

/// `duration_s`, when given: more than 0, at most [`MAX_DURATION_S`].
fn check_duration(duration_s: Option<f64>) -> ControlResult<()> {
    match duration_s {
        Some(d) if !(d.is_finite() && d > 0.0 && d <= MAX_DURATION_S) => Err(
            ControlError::out_of_range("duration_s", d, (0.0, MAX_DURATION_S), "s"),
        ),
        _ => Ok(()),
    }
}

/// A place among the recordings allowed at once while one starts, given
/// back when it has started or failed, or when the request is dropped
/// (the client left while the file was being created).
struct Place {
    state: Arc<Control>,
    id: u64,
    held: bool,
}

impl Place {
    fn take(state: &Arc<Control>) -> ControlResult<Self> {
        let mut book = state.recordings().lock();
        // Counted under the same lock as the reservation: two requests at
        // once cannot both take the last place.
        let running = book.running();
        if running >= MAX_RUNNING {
            return Err(ControlError::conflict(
                "too-many-recordings",
                "Too many recordings",
                format!("{running} recordings are running (at most {MAX_RUNNING}): stop one first"),
            ));
        }
        book.last_id += 1;
        book.starting += 1;
        Ok(Self {
            state: state.clone(),
            id: book.last_id,
            held: true,
        })
    }

    /// Under the caller's lock, so the recording's entry goes in before
    /// another request counts.
    fn give_back(mut self, book: &mut Book) {
        book.starting = book.starting.saturating_sub(1);
        self.held = false;
    }
}

impl Drop for Place {
    fn drop(&mut self) {
        if self.held {
            let mut book = self.state.recordings().lock();
            book.starting = book.starting.saturating_sub(1);
        }
    }
}

/// How many recordings are being written now.
pub(crate) fn running(state: &Arc<Control>) -> usize {
    state.recordings().lock().running()
}

pub(crate) fn list(state: &Arc<Control>) -> Vec<RecordingView> {
    let book = state.recordings().lock();
    book.entries
        .iter()
        .map(|(id, e)| view(*id, e, &e.recorder.status()))
        .collect()
}

fn entry(state: &Arc<Control>, id: u64) -> ControlResult<(Arc<Recorder>, RecordingView)> {
    let book = state.recordings().lock();
    let e = book.entries.get(&id).ok_or_else(|| {
        ControlError::not_found("unknown-recording", format!("no recording with id {id}"))
    })?;
    Ok((e.recorder.clone(), view(id, e, &e.recorder.status())))
}

pub(crate) fn get(state: &Arc<Control>, id: u64) -> ControlResult<RecordingView> {
    Ok(entry(state, id)?.1)
}

/// Stops recording `id` and waits until its file is complete.
pub(crate) async fn stop(state: &Arc<Control>, id: u64) -> ControlResult<RecordingView> {
    let (recorder, _) = entry(state, id)?;
    recorder.stop().await;
    tracing::info!(recording = id, "recording stopped");
    get(state, id)
}

/// Stops every recording still running (the daemon is stopping): each
/// file gets its last chunk, summary and footer.
pub(crate) async fn stop_all(state: &Arc<Control>) {
    let running: Vec<(u64, Arc<Recorder>)> = state
        .recordings()
        .lock()
        .entries
        .iter()
        .filter(|(_, e)| e.recorder.status().state == RecordState::Recording)
        .map(|(id, e)| (*id, e.recorder.clone()))
        .collect();
    let closing = running.into_iter().map(|(id, recorder)| async move {
        let status = recorder.stop().await;
        tracing::info!(recording = id, path = %status.path.display(), "recording closed at shutdown");
    });
    futures_util::future::join_all(closing).await;
}

/// The complete file of recording `id` (409 while it records).
pub(crate) async fn file(state: &Arc<Control>, id: u64) -> ControlResult<(String, Vec<u8>)> {
    let (recorder, v) = entry(state, id)?;
    if v.state == RecordState::Recording {
        return Err(ControlError::conflict(
            "still-recording",
            "Recording not finished",
            format!("recording {id} is still running: stop it (DELETE) or wait for its duration"),
        ));
    }
    let path = recorder.status().path;
    let bytes = tokio::fs::read(&path)
        .await
        .map_err(|e| ControlError::recording_file_unreadable(id, &path, &e))?;
    Ok((v.file, bytes))
}
