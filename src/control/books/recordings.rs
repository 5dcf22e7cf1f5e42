//! The recordings made through the API (`POST /api/v1/recordings`): each
//! one's recorder and what the API says of it. A std `Mutex` guards the
//! book, never held across an `.await`.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;
use utoipa::ToSchema;

use crate::record::{RecordState, RecordStatus, Recorder};

/// A recording as the API reports it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct RecordingView {
    #[schema(example = 1)]
    pub id: u64,
    /// `recording`, `finished` (the file is complete) or `failed`.
    #[schema(value_type = String, example = "recording")]
    pub state: RecordState,
    /// The file's name in the daemon's recordings directory.
    #[schema(example = "rec-1-1764072000.mcap")]
    pub file: String,
    #[schema(example = json!(["sim0"]))]
    pub buses: Vec<String>,
    #[schema(example = 5.0)]
    pub duration_s: Option<f64>,
    /// Unix ms it started and ended.
    #[schema(example = 1764072000000u64)]
    pub started_ms: u64,
    pub ended_ms: Option<u64>,
    /// Messages written, by topic.
    #[schema(example = json!({"/sim0/joint_states": 325, "/jointd/sim0/frames": 12210}))]
    pub messages: BTreeMap<String, u64>,
    /// Frames or targets the recording fell too far behind to keep.
    #[schema(example = 0)]
    pub lost: u64,
    pub error: Option<String>,
}

pub(crate) struct Entry {
    pub recorder: Arc<Recorder>,
    pub buses: Vec<String>,
    pub duration_s: Option<f64>,
}

/// The recordings made through the API.
#[derive(Default)]
pub(crate) struct RecordingBook {
    inner: Mutex<Book>,
}

/// What the book's lock guards.
#[derive(Default)]
pub(crate) struct Book {
    /// The last id handed out.
    pub last_id: u64,
    pub entries: BTreeMap<u64, Entry>,
    /// Recordings whose file is being created (outside the lock): they
    /// count against the cap like running ones.
    pub starting: usize,
}

impl Book {
    /// Recordings being written now, or about to be.
    pub(crate) fn running(&self) -> usize {
        self.starting
            + self
                .entries
                .values()
                .filter(|e| e.recorder.status().state == RecordState::Recording)
                .count()
    }
}

impl RecordingBook {
    pub(crate) fn lock(&self) -> MutexGuard<'_, Book> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }
}

pub(crate) fn view(id: u64, e: &Entry, s: &RecordStatus) -> RecordingView {
    RecordingView {
        id,
        state: s.state,
        file: s
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        buses: e.buses.clone(),
        duration_s: e.duration_s,
        started_ms: s.started_ns / 1_000_000,
        ended_ms: s.ended_ns.map(|n| n / 1_000_000),
        messages: s.messages.clone(),
        lost: s.lost,
        error: s.error.clone(),
    }
}
