//! What a grasp's finger tasks share: the finger as the job started it,
//! the job's plan, and the edit of a finger's view; below the tasks and
//! their watch and limit helpers, so each of those can use them.

use std::time::Instant;

use crate::bus::authority::Epoch;
use crate::bus::BusHandle;
use crate::control::books::grasps::{FingerGrasp, Slot};
use crate::control::books::lock::lock;
use crate::hands::Calibration;

/// One finger as the job started it (device degrees).
#[derive(Debug, Clone)]
pub(crate) struct Finger {
    pub bus: BusHandle,
    pub id: u8,
    /// Its place in the job (a release's goals come in that order).
    pub index: usize,
    pub epoch: Epoch,
    pub cal: Calibration,
    pub close_to_deg: f64,
    pub slot: Slot,
}

/// How the job closes its fingers.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Plan {
    pub grasp_id: u64,
    pub speed_dps: f64,
    pub hold_a: f64,
    pub threshold_a: f64,
    /// When the grasp was called (contact times count from here).
    pub called: Instant,
}

pub(crate) fn set(slot: &Slot, edit: impl FnOnce(&mut FingerGrasp)) {
    edit(&mut lock(slot));
}
