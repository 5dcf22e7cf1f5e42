//! The state the core works on: the buses, the soft limits, the config's
//! options, and the books of running jobs.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::audit::{Audit, Command};
use super::books::{grasps, homing, moves, recordings, streams};
use super::bus_reader::BusReader;
use super::error::{ControlError, ControlResult};
use super::foxglove_stats::FoxgloveStats;
use super::limits::{JointLimits, SoftLimits};
use super::ros2_stats;
use super::teleop::WatchdogDefault;
use crate::bus::BusHandle;

/// The config's options the core reads.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The named hands and their saved poses.
    pub hands: Option<Arc<crate::hands::StateStore>>,
    /// (bus or every bus, id) → name.
    pub joint_names: BTreeMap<(Option<String>, u8), String>,
    pub watchdog: WatchdogDefault,
    /// Where recordings are written (`state_dir/recordings`); absent: a
    /// directory under the system's temporary one.
    pub recordings_dir: Option<std::path::PathBuf>,
    /// The ROS 2 bridge's counters, when it runs.
    pub ros2: Option<Arc<ros2_stats::Ros2Stats>>,
    /// The live Foxglove view's counters, when it runs.
    pub foxglove: Option<Arc<FoxgloveStats>>,
    /// The devices each bus was configured with (its `ids`): the ones the
    /// daemon manages. A bus absent here, or with no ids (it scans for its
    /// devices), manages every device it knows.
    pub managed: BTreeMap<String, Vec<u8>>,
}

/// The buses, limits, options and jobs the core works on.
pub struct Control {
    buses: BTreeMap<String, BusHandle>,
    limits: SoftLimits,
    options: std::sync::OnceLock<Options>,
    moves: moves::MoveBook,
    homings: homing::HomingBook,
    grasps: grasps::GraspBook,
    recordings: recordings::RecordingBook,
    streams: Arc<streams::StreamBook>,
    audit: Audit,
    /// Buses whose port is lent to the doctor now: one check at a time.
    pub(in crate::control) doctoring: std::sync::Mutex<std::collections::BTreeSet<String>>,
}

impl Control {
    pub fn new(buses: Vec<BusHandle>, limits: SoftLimits) -> Self {
        Self {
            buses: buses
                .into_iter()
                .map(|h| (h.name().to_owned(), h))
                .collect(),
            limits,
            options: std::sync::OnceLock::new(),
            moves: Default::default(),
            homings: Default::default(),
            grasps: Default::default(),
            recordings: Default::default(),
            streams: Default::default(),
            audit: Audit::default(),
            doctoring: Default::default(),
        }
    }

    /// Every live teleop stream, by client.
    pub fn stream_book(&self) -> &Arc<streams::StreamBook> {
        &self.streams
    }

    /// Every bus's handle: the core's own (front-ends read through [`Self::readers`]).
    pub(in crate::control) fn buses(&self) -> impl Iterator<Item = &BusHandle> {
        self.buses.values()
    }

    /// A bus's handle: the core's own (front-ends read through [`Self::reader`]).
    pub(in crate::control) fn bus(&self, name: &str) -> ControlResult<&BusHandle> {
        self.buses
            .get(name)
            .ok_or_else(|| ControlError::unknown_bus(name))
    }

    /// Tells who sent `cmd` (to the log, and to the events of bus `bus`,
    /// or of every bus when the command names none).
    pub(crate) fn tell(&self, cmd: &Command<'_>, bus: Option<&str>) {
        match bus {
            Some(name) => self.audit.tell(cmd, self.buses.get(name).into_iter()),
            None => self.audit.tell(cmd, self.buses.values()),
        }
    }

    /// Every bus, read only, in name order.
    pub fn readers(&self) -> impl Iterator<Item = BusReader> + '_ {
        self.buses.values().map(BusReader::new)
    }

    /// Bus `name`, read only; 404 when the daemon has none by that name.
    pub fn reader(&self, name: &str) -> ControlResult<BusReader> {
        self.bus(name).map(BusReader::new)
    }

    /// The options (set once, at start; a second call is refused and gets
    /// its options back).
    pub fn set_options(&self, options: Options) -> Result<(), Box<Options>> {
        self.options.set(options).map_err(Box::new)
    }

    fn options(&self) -> &Options {
        static DEFAULTS: std::sync::OnceLock<Options> = std::sync::OnceLock::new();
        self.options
            .get()
            .unwrap_or_else(|| DEFAULTS.get_or_init(Options::default))
    }

    /// The named hands and their poses (none configured: an empty store).
    pub(crate) fn hands(&self) -> Option<&crate::hands::StateStore> {
        self.options().hands.as_deref()
    }

    /// The moves started through any front-end.
    pub(crate) fn moves(&self) -> &moves::MoveBook {
        &self.moves
    }

    /// The homing jobs started through any front-end.
    pub(crate) fn homings(&self) -> &homing::HomingBook {
        &self.homings
    }

    /// The grasp jobs started through any front-end.
    pub(crate) fn grasps(&self) -> &grasps::GraspBook {
        &self.grasps
    }

    /// The recordings started through any front-end.
    pub(crate) fn recordings(&self) -> &recordings::RecordingBook {
        &self.recordings
    }

    /// Names and calibrations of the joints as every edge gives them (REST,
    /// recordings, ROS 2): a hand's joint name, else the configured name,
    /// else `<bus>_<id>`.
    pub(crate) fn joint_labeler(self: &Arc<Self>) -> crate::record::joint_states::Labeler {
        let control = self.clone();
        Arc::new(move |bus: &str, id: u8| {
            let hand_name = control.hands().and_then(|store| {
                store
                    .hands()
                    .iter()
                    .flat_map(|h| h.joints.iter())
                    .find(|j| j.bus == bus && j.id == id)
                    .map(|j| j.name.clone())
            });
            let name = hand_name
                .or_else(|| control.joint_name(bus, id).map(str::to_owned))
                .unwrap_or_else(|| format!("{bus}_{id}"));
            (name, control.calibration(bus, id))
        })
    }

    /// The ROS 2 bridge's counters, when it runs.
    pub(crate) fn ros2(&self) -> Option<&ros2_stats::Ros2Stats> {
        self.options().ros2.as_deref()
    }

    /// The live Foxglove view's counters, when it runs.
    pub(crate) fn foxglove(&self) -> Option<&FoxgloveStats> {
        self.options().foxglove.as_deref()
    }

    /// Where recordings are written.
    pub(crate) fn recordings_dir(&self) -> std::path::PathBuf {
        self.options().recordings_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("jointd-recordings-{}", std::process::id()))
        })
    }

    pub fn limits(&self, bus: &str, id: u8) -> JointLimits {
        self.limits.for_joint(bus, id)
    }

    /// Whether the daemon manages device `id` of `bus`: one of the bus's
    /// configured ids, or any device on a bus configured with none.
    pub(crate) fn managed(&self, bus: &str, id: u8) -> bool {
        self.options()
            .managed
            .get(bus)
            .filter(|ids| !ids.is_empty())
            .map_or(true, |ids| ids.contains(&id))
    }

    /// The calibration of joint `id` on `bus`: how its angles read at the API.
    pub(crate) fn calibration(&self, bus: &str, id: u8) -> crate::hands::Calibration {
        self.hands()
            .map_or(crate::hands::Calibration::IDENTITY, |store| {
                store.calibration(bus, id)
            })
    }

    /// A joint's name: what its `[[hand]]` calls it, else its `[[joint]]`
    /// name in the config file; the same on every front-end (the device
    /// list, telemetry, recordings, ROS 2).
    pub fn joint_name(&self, bus: &str, id: u8) -> Option<&str> {
        let by_hand = self.hands().and_then(|store| {
            store
                .hands()
                .iter()
                .flat_map(|h| h.joints.iter())
                .find(|j| j.bus == bus && j.id == id)
                .map(|j| j.name.as_str())
        });
        let names = &self.options().joint_names;
        by_hand.or_else(|| {
            names
                .get(&(Some(bus.to_owned()), id))
                .or_else(|| names.get(&(None, id)))
                .map(String::as_str)
        })
    }

    /// What applies to a teleop stream that declares no watchdog of its own.
    pub fn watchdog_default(&self) -> WatchdogDefault {
        self.options().watchdog
    }
}

/// Names the buses.
impl std::fmt::Debug for Control {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let buses: Vec<&str> = self.buses().map(BusHandle::name).collect();
        f.debug_struct("Control")
            .field("buses", &buses)
            .finish_non_exhaustive()
    }
}
