//! The grasp jobs started through any front-end: each finger's state as
//! its task writes it (for `GET`), the command the job's fingers follow
//! (hold, release, stop) and whether the job ended. A std `Mutex` per
//! finger and one for the book, never held across an `.await` (the book's
//! is taken before a finger's, never the other way).
//!
//! One grasp per joint: a job is added only if none of its joints is in a
//! job still running, checked under the book's lock (two grasps would each
//! write back the limit the other had reduced).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use serde::Serialize;
use tokio::sync::watch;
use utoipa::ToSchema;

use crate::control::books::lock::lock;

/// Jobs kept for `GET` after they ended.
const KEPT: usize = 64;

/// Where one finger of a grasp stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum FingerState {
    /// Its current limit is being reduced (no finger moves before every
    /// finger's limit is written and verified).
    Starting,
    /// Closing at the asked speed, feeling for contact.
    Closing,
    /// In contact, pressing with the hold current.
    Holding,
    /// Reached its closing limit without touching anything; it stays there.
    NoContact,
    /// It held something and the current fell: the object is gone. The
    /// finger stays where it was when that was seen.
    Lost,
    /// Opening after `release`.
    Releasing,
    /// Opened by `release`.
    Released,
    /// Held where it was by `stop`, or taken over by another command.
    Stopped,
    /// An e-stop, a disable, a reset, a mode change, a fault or the joint
    /// going offline ended it.
    Aborted,
    /// It could not start (its limit could not be reduced, or the hold
    /// current does not fit the joint).
    Failed,
}

impl FingerState {
    /// Still under the job's control (its task runs).
    pub(crate) fn live(self) -> bool {
        matches!(
            self,
            Self::Starting
                | Self::Closing
                | Self::Holding
                | Self::NoContact
                | Self::Lost
                | Self::Releasing
        )
    }
}

/// One finger of a grasp job. Angles in the joint's calibrated frame.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct FingerGrasp {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    /// The joint's name in the hand.
    #[schema(example = "index")]
    pub joint: String,
    pub state: FingerState,
    /// It touched something (stays true after a loss or a release).
    pub contact: bool,
    /// Where contact began, degrees.
    #[schema(example = 31.5)]
    pub contact_deg: Option<f64>,
    /// From the grasp's call to contact, ms.
    #[schema(example = 420.0)]
    pub contact_after_ms: Option<f64>,
    /// The q current it draws now (smoothed over a few samples), A; the
    /// holding current while it holds.
    #[schema(example = 0.2)]
    pub q_current_a: Option<f64>,
    /// Where it closes to at most, degrees.
    #[schema(example = 90.0)]
    pub close_to_deg: f64,
    /// Where it stood when the grasp began (a plain release opens back
    /// to it), degrees.
    #[schema(example = 0.0)]
    pub start_deg: f64,
    /// Its current limit before the grasp, A (INFO_04).
    #[schema(example = 0.75)]
    pub previous_current_limit_a: Option<f64>,
    /// True only when the current limit read back after the grasp ended
    /// shows the previous one (written back, or never changed).
    #[schema(example = true)]
    pub current_limit_restored: bool,
    /// Why it failed, stopped or was aborted.
    pub reason: Option<String>,
}

pub(crate) type Slot = Arc<Mutex<FingerGrasp>>;

/// What the fingers of a job are told to do next.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Command {
    /// Close and hold (the job's start).
    Hold,
    /// Open: each finger (in job order) to its device angle at `speed_dps`
    /// (`None`: that finger has nothing to open to; it stops).
    Release {
        goals: Vec<Option<f64>>,
        speed_dps: f64,
    },
    /// Hold each finger where it is and end.
    Stop,
}

/// What the grasp was asked.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub(crate) struct GraspSettings {
    /// Closing speed at the output, °/s.
    #[schema(example = 30.0)]
    pub speed_dps: f64,
    /// The current limit each finger holds with, A.
    #[schema(example = 0.2)]
    pub hold_current_a: f64,
    /// The rise of q current over the free-air one that counts as contact, A.
    #[schema(example = 0.06)]
    pub contact_threshold_a: f64,
}

/// A grasp job as the API reports it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct GraspView {
    #[schema(example = 1)]
    pub id: u64,
    #[schema(example = "right")]
    pub hand: String,
    /// `running` while any finger is under the grasp's control; then
    /// `done` (each finger's state says how it ended).
    #[schema(example = "running")]
    pub state: &'static str,
    pub settings: GraspSettings,
    pub fingers: Vec<FingerGrasp>,
}

/// One job: its fingers, the command they follow, whether it ended.
pub(crate) struct Job {
    pub hand: String,
    pub settings: GraspSettings,
    pub slots: Vec<Slot>,
    pub command: watch::Sender<Command>,
    pub done: watch::Sender<bool>,
}

impl Job {
    pub(crate) fn new(hand: String, settings: GraspSettings, slots: Vec<Slot>) -> Arc<Self> {
        Arc::new(Self {
            hand,
            settings,
            slots,
            command: watch::channel(Command::Hold).0,
            done: watch::channel(false).0,
        })
    }

    fn running(&self) -> bool {
        !*self.done.borrow()
    }
}

/// A joint that is in a running grasp.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Busy {
    pub job: u64,
    pub bus: String,
    pub id: u8,
}

/// The grasp jobs.
#[derive(Default)]
pub(crate) struct GraspBook {
    inner: Mutex<(u64, BTreeMap<u64, Arc<Job>>)>,
    /// Release and stop calls waiting for their grasp to end.
    waiting: AtomicUsize,
}

/// Release and stop calls that may wait at once for their grasp to end:
/// each holds a connection for up to the end's bound, and a flood of them
/// must leave room for every other request (the e-stop's first). Beyond,
/// a call's command still applies; its answer does not wait.
pub(crate) const MAX_WAITING: usize = 32;

/// One waiting call's place, given back when it ends.
#[derive(Debug)]
pub(crate) struct WaitSlot<'a>(&'a AtomicUsize);

impl Drop for WaitSlot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

impl GraspBook {
    /// A place among the calls waiting for a grasp to end, if one is free.
    pub(crate) fn wait_slot(&self) -> Option<WaitSlot<'_>> {
        let mut n = self.waiting.load(Ordering::Acquire);
        loop {
            if n >= MAX_WAITING {
                return None;
            }
            match self
                .waiting
                .compare_exchange(n, n + 1, Ordering::AcqRel, Ordering::Acquire)
            {
                Ok(_) => return Some(WaitSlot(&self.waiting)),
                Err(now) => n = now,
            }
        }
    }
}

fn running_in(book: &BTreeMap<u64, Arc<Job>>, bus: &str, id: u8) -> Option<u64> {
    book.iter().find_map(|(n, job)| {
        (job.running()
            && job.slots.iter().any(|s| {
                let f = lock(s);
                f.bus == bus && f.id == id
            }))
        .then_some(*n)
    })
}

impl GraspBook {
    /// The running grasp that has joint `id` of `bus`, if any.
    pub(crate) fn running_job(&self, bus: &str, id: u8) -> Option<u64> {
        running_in(&lock(&self.inner).1, bus, id)
    }

    /// Adds a job, unless one of its joints is in a running one.
    pub(crate) fn add(&self, job: Arc<Job>) -> Result<u64, Busy> {
        let mut book = lock(&self.inner);
        for slot in &job.slots {
            let (bus, id) = {
                let f = lock(slot);
                (f.bus.clone(), f.id)
            };
            if let Some(n) = running_in(&book.1, &bus, id) {
                return Err(Busy { job: n, bus, id });
            }
        }
        book.0 += 1;
        let n = book.0;
        book.1.insert(n, job);
        while book.1.len() > KEPT {
            let oldest_ended = book.1.iter().find(|(_, j)| !j.running()).map(|(n, _)| *n);
            match oldest_ended {
                Some(n) => drop(book.1.remove(&n)),
                None => break,
            }
        }
        Ok(n)
    }

    /// The finger of a running grasp that holds joint `id` of `bus` with a
    /// reduced current limit not yet handed back, if any.
    pub(crate) fn reduced_limit(&self, bus: &str, id: u8) -> Option<Slot> {
        let book = lock(&self.inner);
        book.1
            .values()
            .filter(|job| job.running())
            .flat_map(|job| job.slots.iter())
            .find(|slot| {
                let f = lock(slot);
                f.bus == bus
                    && f.id == id
                    && f.previous_current_limit_a.is_some()
                    && !f.current_limit_restored
            })
            .cloned()
    }

    pub(crate) fn job(&self, id: u64) -> Option<Arc<Job>> {
        lock(&self.inner).1.get(&id).cloned()
    }

    pub(crate) fn view(&self, id: u64) -> Option<GraspView> {
        let job = self.job(id)?;
        Some(GraspView {
            id,
            hand: job.hand.clone(),
            state: if job.running() { "running" } else { "done" },
            settings: job.settings,
            fingers: job.slots.iter().map(|s| lock(s).clone()).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn at_most_max_waiting_calls_wait_and_a_place_comes_back_when_one_ends() {
        let book = GraspBook::default();
        let mut held: Vec<WaitSlot<'_>> = (0..MAX_WAITING)
            .map(|n| book.wait_slot().unwrap_or_else(|| panic!("place {n}")))
            .collect();
        assert!(
            book.wait_slot().is_none(),
            "call {} may not wait",
            MAX_WAITING + 1
        );
        held.pop();
        let again = book.wait_slot();
        assert!(again.is_some(), "a place given back");
        assert!(book.wait_slot().is_none(), "and taken again");
    }
}
