//! What a simulated bus is made of: its device ids, starting baud, timing
//! constants, optional flash state file, and the errors of building one.

use std::path::PathBuf;
use std::time::Duration;

use crate::protocol::{is_device_id, BaudLevel};

pub use super::error::SimError;

use super::firmware::Firmware;
use crate::transport::adapter::AdapterModel;

/// SPEC §1 leaves the turnaround undocumented; the simulator's default.
pub(crate) const DEFAULT_TURNAROUND: Duration = Duration::from_micros(100);
/// SPEC §4.1: "about 1 s" of encoder alignment after the first enable.
pub(crate) const DEFAULT_ALIGN_TIME: Duration = Duration::from_secs(1);
/// Power-up to the spontaneous INFO_01 (a few ms of firmware start-up).
pub(crate) const DEFAULT_BOOT_DELAY: Duration = Duration::from_millis(5);
/// How long a blocked joint pushes before the device latches a stall fault.
pub(crate) const DEFAULT_STALL_FAULT_AFTER: Duration = Duration::from_secs(3);
/// Firmware the simulated modules report (≥ 124: 50000 rpm speed base).
pub(crate) const DEFAULT_SOFT_VER: u8 = 128;
/// Frame log ring size.
pub(crate) const DEFAULT_LOG_CAPACITY: usize = 100_000;
/// Seed of the simulator's noise and fault dice (reproducible by default).
pub(crate) const DEFAULT_SEED: u64 = 0x5EED_1D0C;

/// Everything a simulated bus is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// One device per entry, in bus order; duplicates make id conflicts.
    pub ids: Vec<u8>,
    /// The baud the devices start at (unless a state file says otherwise).
    pub baud: u32,
    /// Request's last byte to reply's first byte.
    pub turnaround: Duration,
    /// Duration of `mcAlign` after the first enable since power-up.
    pub align_time: Duration,
    /// Power-up to the spontaneous INFO_01.
    pub boot_delay: Duration,
    /// Where flash contents (ids, parameters) survive a restart, as JSON.
    pub state_file: Option<PathBuf>,
    pub stall_fault_after: Duration,
    pub soft_ver: u8,
    pub log_capacity: usize,
    pub seed: u64,
    /// The protocol revision each device's firmware implements (default:
    /// V2.0.1 for every device); see [`super::firmware`].
    pub firmware: Firmware,
    /// The USB adapter between the host's tty and the wire (default:
    /// native, none); see [`super::adapter`].
    pub adapter: AdapterModel,
    /// Run the simulator thread under SCHED_FIFO if the system allows it:
    /// tighter delivery times on a busy machine. Off by default (it is a
    /// privilege, and a spinning real-time thread competes with everything).
    pub realtime: bool,
    /// Mechanical end stops: (device id, output angle in degrees of the
    /// factory zero). The joint cannot pass one; pushing against it draws
    /// current up to the cap and, held long enough, faults with a stall,
    /// like any obstacle. What homing looks for.
    pub hard_stops: Vec<(u8, f64)>,
    /// Compliant objects (what a finger grasps): see [`SimObject`].
    pub objects: Vec<SimObject>,
    /// Host writes reach the adapter late by this distribution (a busy
    /// host or USB hub); see [`super::write_delay`]. Only behind an adapter.
    pub write_delay: Option<super::write_delay::WriteDelay>,
    /// The adapter echoes what the host sends: its receiver stays on
    /// while it drives the line, so every host frame comes back to the
    /// host as it was on the wire (`--echo`, [`super::Fault::Echo`]).
    pub echo: bool,
    /// The adapter's driver count of bytes not yet taken (`TIOCOUTQ`)
    /// never falls, though the bytes go out: what confirmed writes must
    /// not believe (`--stuck-count`, [`super::Fault::StuckCount`]). Only
    /// behind an adapter model (a native line has no count).
    pub stuck_count: bool,
}

impl SimConfig {
    pub fn new(ids: Vec<u8>, baud: u32) -> Self {
        Self {
            ids,
            baud,
            turnaround: DEFAULT_TURNAROUND,
            align_time: DEFAULT_ALIGN_TIME,
            boot_delay: DEFAULT_BOOT_DELAY,
            state_file: None,
            stall_fault_after: DEFAULT_STALL_FAULT_AFTER,
            soft_ver: DEFAULT_SOFT_VER,
            log_capacity: DEFAULT_LOG_CAPACITY,
            seed: DEFAULT_SEED,
            firmware: Firmware::default(),
            adapter: AdapterModel::Native,
            realtime: false,
            hard_stops: Vec::new(),
            objects: Vec::new(),
            write_delay: None,
            echo: false,
            stuck_count: false,
        }
    }

    /// Refuses what no bus could be: no devices, a bad id, a baud no module
    /// speaks, a firmware revision for a device the bus does not have.
    pub fn validate(&self) -> Result<(), SimError> {
        if self.ids.is_empty() {
            return Err(SimError::BadIds("a bus needs at least one device".into()));
        }
        if let Some(bad) = self.ids.iter().find(|id| !is_device_id(**id)) {
            return Err(SimError::BadIds(format!(
                "{bad} is not a device id (1..=159)"
            )));
        }
        if self.write_delay.is_some() && !self.adapter.is_latent() {
            return Err(SimError::BadWriteDelay(
                "it needs a USB adapter model (e.g. --adapter ch340): \
                 it is the path to the adapter that is late"
                    .into(),
            ));
        }
        if self.stuck_count && !self.adapter.is_latent() {
            return Err(SimError::BadAdapter(
                "a stuck output count needs a USB adapter model (e.g. --adapter ch340): \
                 a native line has no count"
                    .into(),
            ));
        }
        if BaudLevel::from_baud(self.baud).is_none() {
            return Err(SimError::BadBaud(self.baud));
        }
        if let Some((id, _)) = self
            .hard_stops
            .iter()
            .find(|(id, _)| !self.ids.contains(id))
        {
            return Err(SimError::BadHardStop(format!(
                "device {id} is not on the bus"
            )));
        }
        if let Some(ob) = self.objects.iter().find(|o| !self.ids.contains(&o.id)) {
            return Err(SimError::BadObject(format!(
                "device {} is not on the bus",
                ob.id
            )));
        }
        self.firmware.check_ids(&self.ids)
    }
}

/// An elastic object at one joint: contact starts at `at_deg` (output
/// degrees of the factory zero) and pushes back `nm_per_deg` N·m per degree
/// the joint presses in (see [`super::object`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimObject {
    pub id: u8,
    pub at_deg: f64,
    pub nm_per_deg: f64,
}

/// Parses `"1-16"`, `"1,2,5-7"`, `"3,3"`: ranges and lists, duplicates kept
/// (they reproduce id conflicts), order kept.
pub fn parse_ids(spec: &str) -> Result<Vec<u8>, SimError> {
    crate::protocol::ids::parse_id_list(spec).map_err(SimError::BadIds)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_parse_ranges_lists_and_duplicates() {
        assert_eq!(parse_ids("1-4").unwrap(), vec![1, 2, 3, 4]);
        assert_eq!(parse_ids("1,2,5-7").unwrap(), vec![1, 2, 5, 6, 7]);
        assert_eq!(parse_ids("3,3").unwrap(), vec![3, 3]);
        assert_eq!(parse_ids(" 159 ").unwrap(), vec![159]);
    }

    #[test]
    fn bad_ids_are_refused() {
        for bad in ["", "0", "160", "5-2", "a", "1-", "1,,x"] {
            assert!(parse_ids(bad).is_err(), "{bad:?} should fail");
        }
    }

    #[test]
    fn config_validation_checks_baud_and_ids() {
        assert!(SimConfig::new(vec![1], 500_000).validate().is_ok());
        assert!(SimConfig::new(vec![1], 9600).validate().is_err());
        assert!(SimConfig::new(vec![], 500_000).validate().is_err());
        let mut stuck = SimConfig::new(vec![1], 500_000);
        stuck.stuck_count = true;
        assert!(stuck.validate().is_err(), "no count on a native line");
        stuck.adapter = AdapterModel::Ch340;
        assert!(stuck.validate().is_ok());
    }
}
