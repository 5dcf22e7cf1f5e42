//! The control core: every way to move a joint (REST, WebSocket, ROS 2,
//! moves, poses, homing) goes through here, as equals. It owns the soft
//! limits and target checks, moves, homing, calibration, the teleop
//! watchdog policy and its one joint reference type; it speaks its own
//! error ([`ControlError`]), which each front-end maps once. Whether a
//! frame may still go out is decided below it, by the bus owner's motion
//! authority ([`crate::bus::authority`]): the core admits a command under a
//! joint's epoch, the owner drops it once that epoch has passed.
//!
//! # Layout
//! One-way layers: each file imports only from files above it.
//! - [`error`]: [`ControlError`], typed refusals with the field and range at fault.
//! - `lock`: a job's slot under a std `Mutex`, taken even when poisoned.
//! - [`estop`]: the e-stop's fan-out over buses and its report.
//! - [`device`]: what a device's published state says (firmware, angle, enabled).
//! - [`limits`]: per-joint soft limits from the config.
//! - [`joints`]: [`JointRef`], device ids, known devices, joints named by hand.
//! - [`targets`]: physical targets → raw setpoints, checked; admission under the authority.
//! - [`velocity`]: a velocity command as a position target toward the soft limit at that speed.
//! - `batch`: one resolver of target batches for the teleop front-ends (WebSocket, ROS 2).
//! - `calibration`: saving a joint's calibration (REST and homing).
//! - [`teleop`]: the watchdog policy, its default, and what firing it does.
//! - [`watchdog`]: the one teleop watchdog (WebSocket connections and the ROS 2 bridge).
//! - [`stream_book`]: who streams setpoints to which joints now (the dashboard shows it).
//! - [`streams`]: teleop streams, each under the epoch it began with; ended streams stay ended.
//! - `move_book`, [`moves`]: moves checked whole, started, stopped; the book of them.
//! - `poses`: going to a hand's saved pose (a move of its joints).
//! - `current_limit`: a current limit lowered by a routine, written back, or owed until it is.
//! - `homing/`: homing jobs, one per joint, bounded (its own layout in `homing/mod.rs`).
//! - `grasp/`: closing a hand's fingers on an object and holding it with a
//!   set current (its own layout in `grasp/mod.rs`).
//! - `recording_book`, `recordings`: recordings' jobs: started, listed, stopped, their files.
//! - `ros2_stats`: the ROS 2 bridge's counters (read by `/metrics` and `/api/v1/ros2`).
//! - this file: [`Control`], the state the core works on.

pub(crate) mod batch;
pub(crate) mod calibration;
pub(crate) mod current_limit;
pub mod device;
pub mod error;
pub mod estop;
pub(crate) mod grasp;
pub(crate) mod homing;
pub mod joints;
pub mod limits;
pub(crate) mod lock;
pub(crate) mod move_book;
pub mod moves;
pub(crate) mod poses;
pub(crate) mod recording_book;
pub(crate) mod recordings;
pub mod ros2_stats;
pub mod stream_book;
pub mod streams;
pub mod targets;
pub mod teleop;
// Its one user so far is the ROS 2 bridge (cargo feature `ros2`).
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod velocity;
pub mod watchdog;

use std::collections::BTreeMap;
use std::sync::Arc;

pub use error::{ControlError, ControlResult};
pub use joints::JointRef;

use crate::bus::BusHandle;
use limits::{JointLimits, SoftLimits};
use teleop::WatchdogDefault;

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
    moves: move_book::MoveBook,
    homings: homing::book::HomingBook,
    grasps: grasp::book::GraspBook,
    recordings: recording_book::RecordingBook,
    streams: std::sync::Arc<stream_book::StreamBook>,
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
        }
    }

    /// Every live teleop stream, by client.
    pub fn stream_book(&self) -> &std::sync::Arc<stream_book::StreamBook> {
        &self.streams
    }

    pub fn buses(&self) -> impl Iterator<Item = &BusHandle> {
        self.buses.values()
    }

    pub fn bus(&self, name: &str) -> ControlResult<&BusHandle> {
        self.buses
            .get(name)
            .ok_or_else(|| ControlError::unknown_bus(name))
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
    pub(crate) fn moves(&self) -> &move_book::MoveBook {
        &self.moves
    }

    /// The homing jobs started through any front-end.
    pub(crate) fn homings(&self) -> &homing::book::HomingBook {
        &self.homings
    }

    /// The grasp jobs started through any front-end.
    pub(crate) fn grasps(&self) -> &grasp::book::GraspBook {
        &self.grasps
    }

    /// The recordings started through any front-end.
    pub(crate) fn recordings(&self) -> &recording_book::RecordingBook {
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

    /// The configured name of a joint (`[[joint]]` in the config file).
    pub fn joint_name(&self, bus: &str, id: u8) -> Option<&str> {
        let names = &self.options().joint_names;
        names
            .get(&(Some(bus.to_owned()), id))
            .or_else(|| names.get(&(None, id)))
            .map(String::as_str)
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
