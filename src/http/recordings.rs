//! Recordings made through the API (`POST /api/v1/recordings`): started,
//! listed, stopped, downloaded. The files go to the recordings directory
//! (`state_dir/recordings`, else a directory under the system's temporary
//! one); a std `Mutex` guards the book, never held across an `.await`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use utoipa::ToSchema;

use crate::bus::BusHandle;
use crate::http::error::{ApiError, ApiResult};
use crate::http::recording_book::{view, Entry, RecordingView};
use crate::http::state::AppState;
use crate::record::mcap_file::SideEncoding;
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

/// Checks the request and starts the recording.
pub(crate) fn start(state: &AppState, req: &RecordingRequest) -> ApiResult<RecordingView> {
    if let Some(d) = req.duration_s {
        if !(d.is_finite() && d > 0.0 && d <= MAX_DURATION_S) {
            return Err(ApiError::out_of_range(
                "duration_s",
                d,
                (0.0, MAX_DURATION_S),
                "s",
            ));
        }
    }
    let buses: Vec<BusHandle> = match &req.buses {
        Some(names) if names.is_empty() => {
            return Err(ApiError::invalid("buses", "buses is empty"))
        }
        Some(names) => names
            .iter()
            .map(|n| state.bus(n).cloned())
            .collect::<Result<_, crate::control::ControlError>>()?,
        None => state.buses().cloned().collect(),
    };
    let dir = state.recordings_dir();
    std::fs::create_dir_all(&dir).map_err(|e| {
        ApiError::state_unwritable(format!("recordings directory {}: {e}", dir.display()))
    })?;
    let book = state.recordings();
    let mut inner = book.lock();
    // Counted under the same lock as the insert below: two requests at once
    // cannot both take the last place.
    let running = running_in(&inner.1);
    if running >= MAX_RUNNING {
        return Err(ApiError::conflict(
            "too-many-recordings",
            "Too many recordings",
            format!("{running} recordings are running (at most {MAX_RUNNING}): stop one first"),
        ));
    }
    let id = inner.0 + 1;
    let started_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let path: PathBuf = dir.join(format!("rec-{id}-{started_s}.mcap"));
    let names: Vec<String> = buses.iter().map(|b| b.name().to_owned()).collect();
    let recorder = Recorder::start(
        buses,
        state.joint_labeler(),
        path,
        req.duration_s.map(Duration::from_secs_f64),
        if req.bag_compatible.unwrap_or(false) {
            SideEncoding::RosString
        } else {
            SideEncoding::Json
        },
    )
    .map_err(|e| ApiError::state_unwritable(e.to_string()))?;
    inner.0 = id;
    let entry = Entry {
        recorder: Arc::new(recorder),
        buses: names,
        duration_s: req.duration_s,
    };
    let v = view(id, &entry, &entry.recorder.status());
    tracing::info!(recording = id, file = %v.file, buses = ?v.buses, duration_s = ?v.duration_s, "recording started");
    inner.1.insert(id, entry);
    Ok(v)
}

/// How many recordings are being written now.
pub(crate) fn running(state: &AppState) -> usize {
    running_in(&state.recordings().lock().1)
}

fn running_in(entries: &std::collections::BTreeMap<u64, Entry>) -> usize {
    entries
        .values()
        .filter(|e| e.recorder.status().state == RecordState::Recording)
        .count()
}

pub(crate) fn list(state: &AppState) -> Vec<RecordingView> {
    let inner = state.recordings().lock();
    inner
        .1
        .iter()
        .map(|(id, e)| view(*id, e, &e.recorder.status()))
        .collect()
}

fn entry(state: &AppState, id: u64) -> ApiResult<(Arc<Recorder>, RecordingView)> {
    let inner = state.recordings().lock();
    let e = inner.1.get(&id).ok_or_else(|| {
        ApiError::not_found("unknown-recording", format!("no recording with id {id}"))
    })?;
    Ok((e.recorder.clone(), view(id, e, &e.recorder.status())))
}

pub(crate) fn get(state: &AppState, id: u64) -> ApiResult<RecordingView> {
    Ok(entry(state, id)?.1)
}

/// Stops recording `id` and waits until its file is complete.
pub(crate) async fn stop(state: &AppState, id: u64) -> ApiResult<RecordingView> {
    let (recorder, _) = entry(state, id)?;
    recorder.stop().await;
    tracing::info!(recording = id, "recording stopped");
    get(state, id)
}

/// Stops every recording still running (the daemon is stopping): each
/// file gets its last chunk, summary and footer.
pub(crate) async fn stop_all(state: &AppState) {
    let running: Vec<(u64, Arc<Recorder>)> = state
        .recordings()
        .lock()
        .1
        .iter()
        .filter(|(_, e)| e.recorder.status().state == RecordState::Recording)
        .map(|(id, e)| (*id, e.recorder.clone()))
        .collect();
    for (id, recorder) in running {
        let status = recorder.stop().await;
        tracing::info!(recording = id, path = %status.path.display(), "recording closed at shutdown");
    }
}

/// The complete file of recording `id` (409 while it records).
pub(crate) async fn file(state: &AppState, id: u64) -> ApiResult<(String, Vec<u8>)> {
    let (recorder, v) = entry(state, id)?;
    if v.state == RecordState::Recording {
        return Err(ApiError::conflict(
            "still-recording",
            "Recording not finished",
            format!("recording {id} is still running: stop it (DELETE) or wait for its duration"),
        ));
    }
    let path = recorder.status().path;
    let bytes = tokio::fs::read(&path).await.map_err(|e| {
        ApiError::state_unwritable(format!("recording file {}: {e}", path.display()))
    })?;
    Ok((v.file, bytes))
}
