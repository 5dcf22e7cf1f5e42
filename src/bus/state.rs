//! What a bus owner publishes: its snapshot (link, devices, counters,
//! rates), its events, the frame log entries and the wire acknowledgements.

use std::collections::BTreeMap;
use std::time::{Instant, SystemTime};

use serde::Serialize;

use crate::protocol::CtrlMode;

use super::setpoints::Setpoint;

/// Up, down (port lost, retrying), or not yet opened.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum LinkState {
    Opening,
    Up,
    Down { reason: String, retry_in_ms: u64 },
}

impl LinkState {
    /// The state's name as the API and the metrics show it.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Opening => "opening",
            Self::Up => "up",
            Self::Down { .. } => "down",
        }
    }
}

/// Latest knowledge of one device.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DeviceState {
    pub dev_id: u8,
    pub online: bool,
    pub info01: Option<(crate::protocol::Info01, Instant)>,
    pub info02: Option<(crate::protocol::Info02, Instant)>,
    /// The mode the daemon last set (the device does not report it; power-up is position).
    pub mode: Option<CtrlMode>,
    /// The target last put on the wire.
    pub target_sent: Option<Setpoint>,
    /// False while the device may hold a target the daemon does not know:
    /// not heard yet, or found enabled at start (`on_start = "keep"`) and
    /// sent nothing since. `target_sent` is then `None` meaning unknown.
    pub target_known: bool,
    pub missed_polls: u32,
    /// Why the daemon holds the joint for disabled, until it is enabled
    /// again (or seen driving its motor): `None` while enabled or before
    /// anything disabled it.
    pub disabled_reason: Option<DisabledReason>,
    /// Resets (power cycles) detected since the daemon started.
    pub resets: u64,
    /// The latest of them.
    pub last_reset: Option<ResetRecord>,
    /// Control updates and telemetry samples per second over the last second.
    pub control_hz: f64,
    pub telemetry_hz: f64,
    /// Its protocol revision, once the config or the device told
    /// (`None` while an `auto` device has not been asked yet).
    pub firmware: Option<crate::bus::firmware::DeviceFirmware>,
}

impl DeviceState {
    /// The firmware the device reported in INFO_01, else the newer 50000
    /// rpm speed base (an rpm then maps to at most the asked speed on older
    /// firmware, never more).
    pub fn firmware_version(&self) -> crate::protocol::units::FirmwareVersion {
        self.info01.as_ref().map_or(
            crate::protocol::units::FirmwareVersion::SPEED_BASE_50K,
            |(i, _)| i.firmware(),
        )
    }
}

/// Why a joint is disabled, as far as the daemon knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DisabledReason {
    /// The device reset (power cut, brown-out, reboot) and came back disabled.
    Reset,
    /// The device entered its fault state.
    Fault,
    /// An e-stop disabled it.
    Estop,
    /// A disable request (REST, WebSocket, the teleop watchdog).
    Request,
    /// Found enabled when the daemon started, disabled by `on_start = "disable"`.
    OnStart,
    /// The daemon stopped (`on_shutdown = "disable"`).
    Shutdown,
}

impl DisabledReason {
    /// The name in JSON and logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Reset => "reset",
            Self::Fault => "fault",
            Self::Estop => "estop",
            Self::Request => "request",
            Self::OnStart => "on_start",
            Self::Shutdown => "shutdown",
        }
    }
}

/// What told the daemon a device had reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ResetSignal {
    /// Its unsolicited power-up INFO_01 (SPEC §5), after it had been heard before.
    Announcement,
    /// Its state machine back at ready/init/precharge while the daemon
    /// believed it enabled (nothing of the daemon's disabled it).
    StateDropped,
}

impl ResetSignal {
    pub fn name(self) -> &'static str {
        match self {
            Self::Announcement => "announcement",
            Self::StateDropped => "state_dropped",
        }
    }
}

/// One detected reset of a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResetRecord {
    pub seen: ResetSignal,
    /// fsm before (the last INFO_01 the daemon had), and in the reply that showed it.
    pub fsm_before: Option<u8>,
    pub fsm: u8,
    pub at: Instant,
}

/// Counters of one bus, monotonic since start (rates are derived by readers).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct BusCounters {
    pub frames_tx_broadcast: u64,
    pub frames_tx_control: u64,
    pub frames_tx_config: u64,
    pub frames_tx_jog: u64,
    pub frames_rx: u64,
    pub crc_errors: u64,
    pub skipped_bytes: u64,
    pub timeouts: u64,
    pub retries: u64,
    pub unsolicited: u64,
    /// Wire time the daemon scheduled (frames + turnarounds), microseconds.
    pub wire_busy_us: u64,
    pub requests_queued: u64,
    pub setpoints_sent: u64,
    pub reconnects: u64,
    /// Polls (INFO reads of the telemetry plan) sent.
    pub polls: u64,
    /// Setpoints dropped because their id has no device on the bus.
    pub setpoints_dropped: u64,
    /// Setpoints (client targets, move samples, homing steps) dropped
    /// because their joint's motion epoch advanced after they were admitted
    /// (an e-stop, disable, reset, fault, mode change or enable since).
    pub setpoints_stale: u64,
    /// Times the owner caught a panic of its own (a bug): each one took the
    /// bus down and reopened the port, as after an unplug.
    pub owner_panics: u64,
    /// Extra attempts to confirm a write: a read-back asked again, or the
    /// write re-sent (only where that is harmless) after its RES or
    /// read-back was lost or showed the old value.
    pub verify_retries: u64,
    /// Writes that went out but stayed unconfirmed after those retries.
    pub writes_unverified: u64,
    /// `INFO_07` reads asking a device its firmware revision (`firmware = "auto"`).
    pub firmware_probes: u64,
    /// Of those, attempts no reply answered: how V2.0.1 firmware shows
    /// itself, so they count here and not as timeouts.
    pub firmware_probes_unanswered: u64,
    /// Control frames written in front of a poll, in the same write: on a
    /// latent adapter (one USB transfer), and on a native line the frame
    /// after which the control budget makes a poll follow.
    pub frames_tx_batched: u64,
    /// Polls written blind behind a USB adapter: before the previous reply
    /// reached the host (matched when it comes).
    pub polls_pipelined: u64,
    /// Of those, the ones written while the adapter's frame clock was not
    /// known (not learnt yet, or replies read too late to show it): the
    /// wire was held a whole USB frame longer after each.
    pub usb_writes_unclocked: u64,
    /// Writes that came too close to a USB frame boundary to know which
    /// frame took them; the wire was held for the later one (a host that
    /// woke late, not a collision).
    pub usb_writes_ambiguous: u64,
    /// Times the USB pipeline backed off (a collision's aftermath seen)
    /// and stepped back towards the adapter's bound (clean for a while).
    pub usb_backoffs: u64,
    pub usb_recoveries: u64,
    /// Sentinel transfers whose reply came (written a tenth of a USB frame
    /// before their boundary, the wire held a frame longer), and those of
    /// them whose write reached the adapter a frame late.
    pub usb_sentinels: u64,
    pub usb_sentinels_late: u64,
    /// Behind a USB adapter whose port counts what the adapter has not
    /// taken: writes seen taken half a frame or more after the boundary
    /// they were aimed at (each held the wire that much longer, no
    /// collision), and counts that stayed up 4 ms (given up on: evidence).
    pub usb_writes_taken_late: u64,
    pub usb_counts_given_up: u64,
}

/// Latency histograms since start (`/metrics`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BusLatency {
    /// A setpoint's acceptance to the last byte of its frame on the wire.
    pub setpoint_to_wire: crate::histogram::Histogram,
    /// A config/read frame handed to the port to its reply read back.
    pub round_trip: crate::histogram::Histogram,
}

/// Rates over the last statistics window (about one second).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct BusRates {
    pub window_s: f64,
    pub frames_tx_per_s: f64,
    pub broadcast_per_s: f64,
    pub control_per_s: f64,
    /// Config frames: polls, reads and writes.
    pub config_per_s: f64,
    pub frames_rx_per_s: f64,
    pub polls_per_s: f64,
    pub timeouts_per_s: f64,
    /// Share of the window the daemon had the line busy: its frames plus
    /// each reply's turnaround and frame. The simulator is the referee.
    pub wire_utilisation: f64,
    /// Age of setpoints when the last byte of their frame is due on the wire, µs.
    pub setpoint_age_p50_us: u64,
    pub setpoint_age_p99_us: u64,
    pub setpoint_age_max_us: u64,
    /// The reply timeout now in force (request end to giving up), µs: the
    /// model, the configured margin and what the host path's lateness adds.
    pub reply_timeout_us: u64,
    /// How long before a reply is due the owner stops sleeping and watches
    /// the port, µs: how late its sleeps were seen to end (a high quantile),
    /// so the line does not idle after a reply while the thread wakes.
    pub wake_lead_us: u64,
    /// How long after the line model replies reach the owner, µs (a low
    /// quantile): where it starts watching the port for one. A few µs on a
    /// native UART; a pty or a slow USB path adds to it.
    pub reply_lag_us: u64,
}

/// What the owner publishes after every change worth seeing.
#[derive(Debug, Clone, PartialEq)]
pub struct BusSnapshot {
    pub name: String,
    pub path: String,
    pub baud: u32,
    pub link: LinkState,
    pub devices: BTreeMap<u8, DeviceState>,
    pub counters: BusCounters,
    /// Depth of the request queue when published.
    pub queue_depth: usize,
    /// Polls written blind whose reply is still in the adapter.
    pub polls_in_flight: usize,
    pub published_at: Instant,
    pub published_wall: SystemTime,
    /// Rates over the last statistics window.
    pub rates: BusRates,
    /// Latency histograms since start.
    pub latency: BusLatency,
    /// What starting the owner and opening the port found worth telling
    /// (no real-time priority, failed ioctls on a pty, an FTDI latency timer and its fix).
    pub port_notes: Vec<String>,
    /// The adapter timing the bus plans for (`native`, `ftdi:16`, ...).
    pub adapter: String,
    /// One poll's round trip as the host lives it on that adapter, µs.
    pub transaction_us: u64,
    /// Behind a USB adapter: the pipeline's mode, guard and why it last changed.
    pub usb_pipeline: Option<crate::bus::usb::guard::UsbPipelineView>,
}

impl BusSnapshot {
    /// The snapshot of a bus not opened yet.
    pub fn new(name: &str, path: &str, baud: u32) -> Self {
        Self {
            name: name.to_string(),
            path: path.to_string(),
            baud,
            link: LinkState::Opening,
            devices: BTreeMap::new(),
            counters: BusCounters::default(),
            queue_depth: 0,
            polls_in_flight: 0,
            published_at: Instant::now(),
            published_wall: SystemTime::now(),
            rates: BusRates::default(),
            latency: BusLatency::default(),
            port_notes: Vec::new(),
            adapter: "native".into(),
            transaction_us: 0,
            usb_pipeline: None,
        }
    }
}

/// A frame seen on the wire, for the raw frame view.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoggedFrame {
    pub at: SystemTime,
    pub tx: bool,
    pub bytes: [u8; 20],
}

/// The latest setpoint write that reached the wire, for acknowledgements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WireAck {
    /// Highest [`SetpointStore`](super::setpoints::SetpointStore) sequence number whose frame has been written
    /// (every joint of that write is on the wire).
    pub seq: u64,
    /// When the last byte of that frame is due on the wire.
    pub at: Option<Instant>,
}
