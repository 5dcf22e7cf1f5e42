//! The homing jobs started through the API (`POST /api/v1/homing`): each
//! joint's progress as its task writes it, for `GET`. A std `Mutex` per
//! joint and one for the book, never held across an `.await` (the book's
//! is taken before a joint's, never the other way).
//!
//! One job per joint: a job is added only if none of its joints is in a
//! job still running, checked under the book's lock, so two requests
//! cannot both start one (two searches would fight over the joint, and
//! each would write back the limit the other had reduced).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use crate::control::books::lock::lock;

use serde::Serialize;
use utoipa::ToSchema;

/// Jobs kept for `GET` after they ended.
const KEPT: usize = 64;

/// Where a joint's homing stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum HomingState {
    Running,
    /// The stop was found and recorded.
    Homed,
    /// It could not start, or the search timed out.
    Failed,
    /// An e-stop, a fault, a disable or the joint going offline ended it.
    Aborted,
}

/// One joint of a homing job.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct JointHoming {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    pub state: HomingState,
    /// What it does now: `starting`, `searching`, `backing_off`, `restoring`, `done`.
    #[schema(example = "searching")]
    pub phase: &'static str,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// The device angle where the joint stalled, degrees.
    #[schema(example = -30.0)]
    pub hard_stop_device_deg: Option<f64>,
    /// The calibration offset recorded from it.
    #[schema(example = -30.0)]
    pub offset_deg: Option<f64>,
    /// The joint's current limit before homing, A (INFO_04).
    #[schema(example = 0.75)]
    pub previous_current_limit_a: Option<f64>,
    /// True only when the current limit read back after homing shows the
    /// previous one (written back, or never changed).
    #[schema(example = true)]
    pub current_limit_restored: bool,
}

/// A homing job as the API reports it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct HomingView {
    #[schema(example = 1)]
    pub id: u64,
    /// `running` until every joint ended; then `done` (each joint's state
    /// says how).
    #[schema(example = "running")]
    pub state: &'static str,
    pub joints: Vec<JointHoming>,
}

pub(crate) type Slot = Arc<Mutex<JointHoming>>;

/// The homing jobs started through the API.
#[derive(Default)]
pub(crate) struct HomingBook {
    inner: Mutex<(u64, BTreeMap<u64, Vec<Slot>>)>,
}

/// A joint that is in a running homing job.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Busy {
    pub job: u64,
    pub bus: String,
    pub id: u8,
}

fn running_in(book: &BTreeMap<u64, Vec<Slot>>, bus: &str, id: u8) -> Option<u64> {
    book.iter().find_map(|(job, slots)| {
        slots
            .iter()
            .any(|s| {
                let j = lock(s);
                j.state == HomingState::Running && j.bus == bus && j.id == id
            })
            .then_some(*job)
    })
}

impl HomingBook {
    /// The running job that has joint `id` of `bus`, if any.
    pub(crate) fn running_job(&self, bus: &str, id: u8) -> Option<u64> {
        running_in(&lock(&self.inner).1, bus, id)
    }

    /// Adds a job, unless one of its joints is in a running job.
    pub(crate) fn add(&self, slots: Vec<Slot>) -> Result<u64, Busy> {
        let mut book = lock(&self.inner);
        for slot in &slots {
            let (bus, id) = {
                let j = lock(slot);
                (j.bus.clone(), j.id)
            };
            if let Some(job) = running_in(&book.1, &bus, id) {
                return Err(Busy { job, bus, id });
            }
        }
        book.0 += 1;
        let id = book.0;
        book.1.insert(id, slots);
        while book.1.len() > KEPT {
            let oldest_ended = book
                .1
                .iter()
                .find(|(_, s)| s.iter().all(|j| lock(j).state != HomingState::Running))
                .map(|(id, _)| *id);
            match oldest_ended {
                Some(id) => drop(book.1.remove(&id)),
                None => break,
            }
        }
        Ok(id)
    }

    pub(crate) fn view(&self, id: u64) -> Option<HomingView> {
        let book = lock(&self.inner);
        let slots = book.1.get(&id)?;
        let joints: Vec<JointHoming> = slots.iter().map(|s| lock(s).clone()).collect();
        let running = joints.iter().any(|j| j.state == HomingState::Running);
        Some(HomingView {
            id,
            state: if running { "running" } else { "done" },
            joints,
        })
    }
}
