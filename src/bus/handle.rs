//! The cloneable handle through which everything but the bus owner reaches a
//! bus: REST and WebSocket handlers never touch a port.
//!
//! - Setpoints go into a latest-value store ([`SetpointStore`]) that the
//!   scheduler samples; a client faster than the wire overwrites, never queues.
//! - One-shot work (enable, config, reads, scans) is a [`Request`] on a bounded
//!   channel with a oneshot reply.
//! - E-stop is a flag the owner checks before every frame: it beats anything queued.
//! - State flows back through a `watch` of [`BusSnapshot`] and a `broadcast` of [`BusEvent`].
//!
//! Locks here are `std::sync::Mutex`: no lock is held across an `.await`, and
//! the owner is a plain OS thread.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;
use tokio::sync::{broadcast, oneshot, watch};

use crate::protocol::{ConfigParam, CtrlMode, InfoBlock, JogDir, Reply};

use super::error::BusError;

/// A joint target as the wire carries it (raw Q7 degrees, raw Q15 speed).
/// Units and soft limits are checked before a setpoint gets here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Setpoint {
    pub pos_ref: i16,
    pub spd_ref: i16,
}

/// One slot of the latest-value store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoredSetpoint {
    pub setpoint: Setpoint,
    /// Store-wide sequence number of the write that produced this value.
    pub seq: u64,
    /// When the write was accepted (for setpoint-to-wire latency).
    pub accepted: Instant,
}

/// Latest target per joint. Writers overwrite; the scheduler takes what
/// changed since it last looked (`seq` above what it sent).
#[derive(Debug, Default)]
pub struct SetpointStore {
    slots: Mutex<BTreeMap<u8, StoredSetpoint>>,
    next_seq: AtomicU64,
}

impl SetpointStore {
    fn lock(&self) -> MutexGuard<'_, BTreeMap<u8, StoredSetpoint>> {
        self.slots.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Stores targets for several joints at once; returns the sequence number
    /// they share.
    pub fn set(&self, targets: &[(u8, Setpoint)]) -> u64 {
        let seq = self.next_seq.fetch_add(1, Ordering::Relaxed) + 1;
        let accepted = Instant::now();
        let mut slots = self.lock();
        for &(id, setpoint) in targets {
            slots.insert(
                id,
                StoredSetpoint {
                    setpoint,
                    seq,
                    accepted,
                },
            );
        }
        seq
    }

    /// Every stored target with a sequence number above `after`.
    pub fn changed_since(&self, after: u64) -> Vec<(u8, StoredSetpoint)> {
        self.lock()
            .iter()
            .filter(|(_, s)| s.seq > after)
            .map(|(id, s)| (*id, *s))
            .collect()
    }

    pub fn get(&self, id: u8) -> Option<StoredSetpoint> {
        self.lock().get(&id).copied()
    }

    /// Forgets targets (e-stop, disable): a later enable must not jump to a stale target.
    pub fn clear(&self, ids: Option<&[u8]>) {
        let mut slots = self.lock();
        match ids {
            None => slots.clear(),
            Some(ids) => ids.iter().for_each(|id| {
                slots.remove(id);
            }),
        }
    }

    /// Renames a joint's slot after an id change.
    pub fn rename(&self, old: u8, new: u8) {
        let mut slots = self.lock();
        if let Some(s) = slots.remove(&old) {
            slots.insert(new, s);
        }
    }
}

/// Which devices a control request addresses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Targets {
    /// Every known device, in one `0xFF` frame.
    All,
    Ids(Vec<u8>),
}

/// What a verified config write found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WriteOutcome {
    pub dev_id: u8,
    pub index: u8,
    pub value: u16,
    /// How it was confirmed: a RES reply, or a read-back of the INFO block.
    pub verified_by: &'static str,
}

/// What an e-stop did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EstopReport {
    pub bus: String,
    /// Disable frames written (`0xFF` first, then one per known device).
    pub frames_sent: u32,
    /// Queued requests failed because the e-stop preempted them.
    pub preempted_requests: u32,
    /// Time from the call to the first disable frame being handed to the port.
    pub latency_us: u64,
}

type Reply1<T> = oneshot::Sender<Result<T, BusError>>;

/// One-shot work for the bus owner. Each carries its own reply channel.
#[derive(Debug)]
pub enum Request {
    Enable {
        targets: Targets,
        reply: Reply1<()>,
    },
    Disable {
        targets: Targets,
        reply: Reply1<()>,
    },
    Jog {
        dev_id: u8,
        dir: JogDir,
        reply: Reply1<()>,
    },
    /// UPDATE_FIN_ZERO: the current position becomes 0°.
    Rezero {
        dev_id: u8,
        reply: Reply1<()>,
    },
    SetMode {
        dev_id: u8,
        mode: CtrlMode,
        reply: Reply1<()>,
    },
    ReadInfo {
        dev_id: u8,
        block: InfoBlock,
        reply: Reply1<Reply>,
    },
    /// A parameter write, verified by RES or by reading the INFO block back.
    WriteConfig {
        dev_id: u8,
        param: ConfigParam,
        reply: Reply1<WriteOutcome>,
    },
    WriteFlash {
        dev_id: u8,
        reply: Reply1<WriteOutcome>,
    },
    SetId {
        dev_id: u8,
        new_id: u8,
        reply: Reply1<WriteOutcome>,
    },
    /// Changes every device on the bus, then the port.
    SetBaud {
        baud: u32,
        reply: Reply1<()>,
    },
    /// Polls INFO_01 of each id; answers the ids that replied.
    Scan {
        first: u8,
        last: u8,
        reply: Reply1<Vec<u8>>,
    },
}

/// Up, down (port lost, retrying), or not yet opened.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum LinkState {
    Opening,
    Up,
    Down { reason: String, retry_in_ms: u64 },
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
    pub missed_polls: u32,
    /// Control updates and telemetry samples per second over the last second.
    pub control_hz: f64,
    pub telemetry_hz: f64,
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
    pub published_at: Instant,
    pub published_wall: SystemTime,
    /// Rates over the last statistics window.
    pub rates: BusRates,
    /// What opening the port found worth telling (failed ioctls on a pty,
    /// an FTDI latency timer and its fix).
    pub port_notes: Vec<String>,
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
            published_at: Instant::now(),
            published_wall: SystemTime::now(),
            rates: BusRates::default(),
            port_notes: Vec::new(),
        }
    }
}

/// Something subscribers should hear about as it happens.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum BusEvent {
    DeviceOnline {
        bus: String,
        dev_id: u8,
    },
    DeviceOffline {
        bus: String,
        dev_id: u8,
    },
    Fault {
        bus: String,
        dev_id: u8,
        err_code: u8,
        name: &'static str,
    },
    BusUp {
        bus: String,
    },
    BusDown {
        bus: String,
        reason: String,
    },
    IdChanged {
        bus: String,
        old: u8,
        new: u8,
    },
    BaudChanged {
        bus: String,
        baud: u32,
    },
    Estop {
        bus: String,
    },
}

/// A frame seen on the wire, for the raw frame view.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoggedFrame {
    pub at: SystemTime,
    pub tx: bool,
    pub bytes: [u8; 20],
}

/// How long a request may wait for the owner before the caller gives up.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

/// The latest setpoint write that reached the wire, for acknowledgements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WireAck {
    /// Highest [`SetpointStore`] sequence number whose frame has been written
    /// (every joint of that write is on the wire).
    pub seq: u64,
    /// When the last byte of that frame is due on the wire.
    pub at: Option<Instant>,
}

/// State shared by every handle and the owner thread of one bus.
pub struct BusShared {
    pub name: String,
    pub setpoints: SetpointStore,
    /// Bumped by each e-stop call; the owner acts when it sees a value above
    /// the last it handled.
    pub estop_generation: AtomicU64,
    /// The owner's answer: (generation handled, report).
    pub estop_done: watch::Sender<(u64, Option<Result<EstopReport, BusError>>)>,
    pub snapshot: watch::Sender<Arc<BusSnapshot>>,
    pub events: broadcast::Sender<BusEvent>,
    pub wire_acks: watch::Sender<WireAck>,
    pub frame_log: Mutex<std::collections::VecDeque<LoggedFrame>>,
    /// When the latest e-stop was called, for its latency report.
    pub estop_called: Mutex<Option<Instant>>,
    /// Requests handed to the owner and not yet taken.
    pub queued: AtomicUsize,
}

/// How many frames the raw frame view keeps.
pub const FRAME_LOG_LEN: usize = 512;
/// How many one-shot requests may wait for the owner.
pub const REQUEST_QUEUE_LEN: usize = 64;

impl BusShared {
    pub fn new(name: String, initial: BusSnapshot) -> Arc<BusShared> {
        Arc::new(BusShared {
            name,
            setpoints: SetpointStore::default(),
            estop_generation: AtomicU64::new(0),
            estop_done: watch::channel((0, None)).0,
            snapshot: watch::channel(Arc::new(initial)).0,
            events: broadcast::channel(1024).0,
            wire_acks: watch::channel(WireAck::default()).0,
            frame_log: Mutex::new(std::collections::VecDeque::with_capacity(FRAME_LOG_LEN)),
            estop_called: Mutex::new(None),
            queued: AtomicUsize::new(0),
        })
    }

    /// Appends to the raw frame log, dropping the oldest.
    pub fn log_frame(&self, frame: LoggedFrame) {
        let mut log = self.frame_log.lock().unwrap_or_else(|p| p.into_inner());
        if log.len() == FRAME_LOG_LEN {
            log.pop_front();
        }
        log.push_back(frame);
    }

    /// Publishes an event; nobody listening is fine.
    pub fn emit(&self, event: BusEvent) {
        let _ = self.events.send(event);
    }
}

/// A cloneable handle on one bus.
#[derive(Clone)]
pub struct BusHandle {
    shared: Arc<BusShared>,
    requests: std::sync::mpsc::SyncSender<Request>,
}

impl BusHandle {
    pub fn new(shared: Arc<BusShared>, requests: std::sync::mpsc::SyncSender<Request>) -> Self {
        Self { shared, requests }
    }

    pub fn name(&self) -> &str {
        &self.shared.name
    }

    pub fn shared(&self) -> &Arc<BusShared> {
        &self.shared
    }

    /// Stores targets; the scheduler puts them on the wire at its next chance.
    /// Returns the sequence number to match against [`Self::wire_acks`].
    pub fn set_targets(&self, targets: &[(u8, Setpoint)]) -> u64 {
        self.shared.setpoints.set(targets)
    }

    pub fn snapshot(&self) -> Arc<BusSnapshot> {
        self.shared.snapshot.borrow().clone()
    }

    pub fn watch(&self) -> watch::Receiver<Arc<BusSnapshot>> {
        self.shared.snapshot.subscribe()
    }

    pub fn events(&self) -> broadcast::Receiver<BusEvent> {
        self.shared.events.subscribe()
    }

    pub fn wire_acks(&self) -> watch::Receiver<WireAck> {
        self.shared.wire_acks.subscribe()
    }

    /// The last `n` frames seen on the wire, oldest first.
    pub fn recent_frames(&self, n: usize) -> Vec<LoggedFrame> {
        let log = self
            .shared
            .frame_log
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        log.iter()
            .skip(log.len().saturating_sub(n))
            .cloned()
            .collect()
    }

    /// Disables every device on this bus ahead of anything queued, and
    /// reports what was done once the frames are written.
    pub async fn estop(&self) -> Result<EstopReport, BusError> {
        let now = Instant::now();
        self.shared
            .estop_called
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get_or_insert(now);
        let generation = self.shared.estop_generation.fetch_add(1, Ordering::SeqCst) + 1;
        let mut done = self.shared.estop_done.subscribe();
        let wait = async {
            match done.wait_for(|(handled, _)| *handled >= generation).await {
                Ok(state) => state.1.clone().unwrap_or(Err(BusError::Stopped)),
                Err(_) => Err(BusError::Stopped),
            }
        };
        tokio::time::timeout(REQUEST_TIMEOUT, wait)
            .await
            .unwrap_or(Err(BusError::OwnerTimeout))
    }

    async fn call<T>(&self, make: impl FnOnce(Reply1<T>) -> Request) -> Result<T, BusError> {
        let (tx, rx) = oneshot::channel();
        // Counted before sending so the owner never takes one not yet counted.
        self.shared.queued.fetch_add(1, Ordering::Relaxed);
        self.requests.try_send(make(tx)).map_err(|e| {
            self.shared.queued.fetch_sub(1, Ordering::Relaxed);
            match e {
                std::sync::mpsc::TrySendError::Full(_) => BusError::Busy {
                    depth: REQUEST_QUEUE_LEN,
                },
                std::sync::mpsc::TrySendError::Disconnected(_) => BusError::Stopped,
            }
        })?;
        match tokio::time::timeout(REQUEST_TIMEOUT, rx).await {
            Ok(Ok(result)) => result,
            Ok(Err(_)) => Err(BusError::Stopped),
            Err(_) => Err(BusError::OwnerTimeout),
        }
    }

    pub async fn enable(&self, targets: Targets) -> Result<(), BusError> {
        self.call(|reply| Request::Enable { targets, reply }).await
    }

    pub async fn disable(&self, targets: Targets) -> Result<(), BusError> {
        self.call(|reply| Request::Disable { targets, reply }).await
    }

    pub async fn jog(&self, dev_id: u8, dir: JogDir) -> Result<(), BusError> {
        self.call(|reply| Request::Jog { dev_id, dir, reply }).await
    }

    pub async fn rezero(&self, dev_id: u8) -> Result<(), BusError> {
        self.call(|reply| Request::Rezero { dev_id, reply }).await
    }

    pub async fn set_mode(&self, dev_id: u8, mode: CtrlMode) -> Result<(), BusError> {
        self.call(|reply| Request::SetMode {
            dev_id,
            mode,
            reply,
        })
        .await
    }

    pub async fn read_info(&self, dev_id: u8, block: InfoBlock) -> Result<Reply, BusError> {
        self.call(|reply| Request::ReadInfo {
            dev_id,
            block,
            reply,
        })
        .await
    }

    pub async fn write_config(
        &self,
        dev_id: u8,
        param: ConfigParam,
    ) -> Result<WriteOutcome, BusError> {
        self.call(|reply| Request::WriteConfig {
            dev_id,
            param,
            reply,
        })
        .await
    }

    pub async fn write_flash(&self, dev_id: u8) -> Result<WriteOutcome, BusError> {
        self.call(|reply| Request::WriteFlash { dev_id, reply })
            .await
    }

    pub async fn set_id(&self, dev_id: u8, new_id: u8) -> Result<WriteOutcome, BusError> {
        self.call(|reply| Request::SetId {
            dev_id,
            new_id,
            reply,
        })
        .await
    }

    pub async fn set_baud(&self, baud: u32) -> Result<(), BusError> {
        self.call(|reply| Request::SetBaud { baud, reply }).await
    }

    pub async fn scan(&self, first: u8, last: u8) -> Result<Vec<u8>, BusError> {
        self.call(|reply| Request::Scan { first, last, reply })
            .await
    }
}
