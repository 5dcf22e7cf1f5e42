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

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use tokio::sync::{broadcast, oneshot, watch};

use crate::protocol::{ConfigParam, CtrlMode, InfoBlock, JogDir, Reply};

use super::authority::Revoked;
use super::error::BusError;
// The published state and the setpoint store live in their own files; they
// are part of this contract and reachable under `bus::handle::` too.
pub use super::events::BusEvent;
pub use super::setpoints::{Commanded, Setpoint, SetpointStore, Source, StoredSetpoint};
pub use super::state::{
    BusCounters, BusLatency, BusRates, BusSnapshot, DeviceState, DisabledReason, LinkState,
    LoggedFrame, ResetRecord, ResetSignal, WireAck,
};

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

/// What a write to every device did, device by device.
#[derive(Debug)]
pub struct WriteAllOutcome {
    /// One frame to id 0xFF carried the write (every device runs rev
    /// 2.0.8); `false`: one write per device.
    pub one_frame: bool,
    /// Each device's own result, in the order asked.
    pub per_device: Vec<(u8, Result<WriteOutcome, BusError>)>,
}

/// What an e-stop did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct EstopReport {
    pub bus: String,
    /// Disable frames written (`0xFF` first, then one per known device, then `0xFF`).
    pub frames_sent: u32,
    /// Queued requests failed because the e-stop preempted them.
    pub preempted_requests: u32,
    /// Time from the call to the first disable frame being handed to the port.
    pub latency_us: u64,
    /// Devices read back not driving their motor.
    pub confirmed: Vec<u8>,
    /// Devices read back still driving, sent a disable of their own again
    /// (they are also in `confirmed` or `still_enabled`).
    pub disabled_again: Vec<u8>,
    /// Devices still driving after the second disable: not stopped.
    pub still_enabled: Vec<u8>,
    /// Devices whose state could not be read back (offline or silent).
    pub unconfirmed: Vec<u8>,
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
    /// One parameter to every device in `ids` (one frame to 0xFF where
    /// every one runs rev 2.0.8), each verified for itself.
    WriteAll {
        ids: Vec<u8>,
        param: ConfigParam,
        reply: Reply1<WriteAllOutcome>,
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
    /// The port lent to `job` ([`crate::bus::loan`]).
    LendPort {
        job: crate::bus::loan::PortJob,
        reply: Reply1<()>,
    },
}

impl Request {
    /// Answers the request with `err` without running it (bus down, e-stop,
    /// stop). A caller that gave up has dropped its receiver: nothing to tell.
    pub(crate) fn fail(self, err: BusError) {
        match self {
            Request::Enable { reply, .. }
            | Request::Disable { reply, .. }
            | Request::Jog { reply, .. }
            | Request::Rezero { reply, .. }
            | Request::SetMode { reply, .. }
            | Request::SetBaud { reply, .. } => drop(reply.send(Err(err))),
            Request::ReadInfo { reply, .. } => drop(reply.send(Err(err))),
            Request::WriteConfig { reply, .. }
            | Request::WriteFlash { reply, .. }
            | Request::SetId { reply, .. } => drop(reply.send(Err(err))),
            Request::Scan { reply, .. } => drop(reply.send(Err(err))),
            Request::LendPort { reply, .. } => drop(reply.send(Err(err))),
            Request::WriteAll { reply, .. } => drop(reply.send(Err(err))),
        }
    }
}

/// How long a request may wait for the owner before the caller gives up.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

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
    /// Joints following a move, sampled by the owner every control cycle.
    pub motion: super::motion::BusMotion,
    /// Every frame as it is logged, for recordings (sent only while one
    /// listens: nothing is copied otherwise).
    pub frame_tap: broadcast::Sender<LoggedFrame>,
    /// Current limits a routine could not give back yet.
    pub owed_limits: super::owed::OwedLimits,
}

/// How many frames a recording may fall behind before it loses some
/// (counted): ~3 s of a saturated 500000-baud line.
const FRAME_TAP_LEN: usize = 8192;

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
            motion: Default::default(),
            frame_tap: broadcast::channel(FRAME_TAP_LEN).0,
            owed_limits: Default::default(),
        })
    }

    /// Appends to the raw frame log, dropping the oldest.
    pub fn log_frame(&self, frame: LoggedFrame) {
        if self.frame_tap.receiver_count() > 0 {
            let _ = self.frame_tap.send(frame.clone());
        }
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

    /// Stores a client's targets (source [`Source::Rest`]); see
    /// [`Self::set_targets_as`].
    pub fn set_targets(&self, targets: &[(u8, Setpoint)]) -> u64 {
        self.set_targets_as(targets, Source::Rest)
    }

    /// Stores targets written by `source`; the scheduler puts them on the
    /// wire at its next chance. Returns the sequence number to match against
    /// [`Self::wire_acks`]. Each joint leaves the move it followed, if any
    /// (see [`Self::take_over`]).
    /// Each target is admitted now, under its joint's current motion
    /// epoch: the owner drops it if the joint is not enabled.
    pub fn set_targets_as(&self, targets: &[(u8, Setpoint)], source: Source) -> u64 {
        if self.shared.motion.is_active() {
            let ids: Vec<u8> = targets.iter().map(|(id, _)| *id).collect();
            let released = self.shared.motion.release(&ids);
            self.say_done(&released.ended);
        }
        self.shared.setpoints.set(targets, source)
    }

    /// Stores targets each admitted under the epoch it carries (a job that
    /// keeps the epoch it started with); the owner drops those whose joint's
    /// epoch has moved on. Each joint leaves the move it followed, if any.
    pub fn set_targets_under(
        &self,
        targets: &[(u8, Setpoint, super::authority::Epoch)],
        source: Source,
    ) -> u64 {
        if self.shared.motion.is_active() {
            let ids: Vec<u8> = targets.iter().map(|(id, _, _)| *id).collect();
            let released = self.shared.motion.release(&ids);
            self.say_done(&released.ended);
        }
        self.shared.setpoints.set_admitted(targets, source)
    }

    /// Puts joints of this bus on a move (and says so to subscribers);
    /// returns the ids of the moves they left (a new move replaces a
    /// running one joint by joint).
    pub fn follow(&self, followers: Vec<super::motion::Follower>) -> Vec<u64> {
        let released = self.follow_inner(followers);
        self.say_done(&released.ended);
        released.left
    }

    fn follow_inner(&self, followers: Vec<super::motion::Follower>) -> super::motion::Released {
        if let Some(first) = followers.first() {
            self.shared.emit(BusEvent::MoveStarted {
                bus: self.name().to_string(),
                move_id: first.mv.id,
                ids: followers.iter().map(|f| f.dev_id).collect(),
                duration_ms: first.mv.path.duration().as_secs_f64() * 1e3,
            });
        }
        self.shared.motion.follow(followers)
    }

    /// Says to subscribers that a move with joints on this bus was stopped.
    pub fn move_stopped(&self, move_id: u64) {
        self.shared.emit(BusEvent::MoveStopped {
            bus: self.name().to_string(),
            move_id,
        });
    }

    /// Takes joints out of their moves (a newer setpoint); returns those moves.
    pub fn take_over(&self, ids: &[u8]) -> Vec<u64> {
        let released = self.shared.motion.release(ids);
        self.say_done(&released.ended);
        released.left
    }

    /// Moves that ended because every joint left them: done, as for subscribers.
    fn say_done(&self, ended: &[u64]) {
        for &move_id in ended {
            self.shared.emit(BusEvent::MoveDone {
                bus: self.name().to_string(),
                move_id,
            });
        }
    }

    /// Joint `id`'s standing: its motion epoch, enabled, mode.
    pub fn grant(&self, id: u8) -> super::authority::Grant {
        self.shared.setpoints.authority().grant(id)
    }

    /// Who may move which joint on this bus.
    /// Current limits owed to this bus's joints ([`super::owed`]).
    pub fn owed_limits(&self) -> &super::owed::OwedLimits {
        &self.shared.owed_limits
    }

    pub fn authority(&self) -> &super::authority::MotionAuthority {
        self.shared.setpoints.authority()
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
        // Every joint's epoch advances now, not when the owner gets to the
        // e-stop: nothing admitted before (a setpoint, a move, a stream) may
        // reach a joint after this, and nothing is admitted until an enable.
        self.shared.setpoints.revoke(None, Revoked::Estopped);
        let reason = Revoked::Estopped.name();
        for move_id in self.shared.motion.abort_all(reason) {
            self.shared.emit(BusEvent::MoveAborted {
                bus: self.name().to_string(),
                move_id,
                reason: reason.into(),
            });
        }
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
        self.call_within(REQUEST_TIMEOUT, make).await
    }

    async fn call_within<T>(
        &self,
        timeout: Duration,
        make: impl FnOnce(Reply1<T>) -> Request,
    ) -> Result<T, BusError> {
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
        match tokio::time::timeout(timeout, rx).await {
            Ok(Ok(result)) => result,
            Ok(Err(_)) => Err(BusError::Stopped),
            Err(_) => Err(BusError::OwnerTimeout),
        }
    }

    /// Lends the port to `job` on the owner's thread, with every joint
    /// disabled (refused otherwise: `WrongState`); its answer once the port
    /// is back. `within` bounds the wait for the owner and the job.
    pub async fn lend_port<T: Send + 'static>(
        &self,
        within: Duration,
        job: impl FnOnce(&mut dyn crate::transport::Transport, &crate::bus::loan::PortLoan) -> T
            + Send
            + 'static,
    ) -> Result<T, BusError> {
        let (tx, rx) = oneshot::channel();
        let job = crate::bus::loan::PortJob::new(move |port, loan| {
            drop(tx.send(job(port, loan)));
        });
        self.call_within(within, |reply| Request::LendPort { job, reply })
            .await?;
        rx.await.map_err(|_| BusError::Stopped)
    }

    pub async fn enable(&self, targets: Targets) -> Result<(), BusError> {
        self.call(|reply| Request::Enable { targets, reply }).await
    }

    /// The joints' epochs advance at the call, before the owner writes a
    /// frame: what was admitted for them stops here, even if the disable fails.
    pub async fn disable(&self, targets: Targets) -> Result<(), BusError> {
        let ids = match &targets {
            Targets::All => None,
            Targets::Ids(ids) => Some(ids.as_slice()),
        };
        self.shared.setpoints.revoke(ids, Revoked::Disabled);
        self.call(|reply| Request::Disable { targets, reply }).await
    }

    pub async fn jog(&self, dev_id: u8, dir: JogDir) -> Result<(), BusError> {
        self.call(|reply| Request::Jog { dev_id, dir, reply }).await
    }

    pub async fn rezero(&self, dev_id: u8) -> Result<(), BusError> {
        self.call(|reply| Request::Rezero { dev_id, reply }).await
    }

    /// Nothing admitted before the change applies after it, and nothing is
    /// admitted while it is on its way.
    pub async fn set_mode(&self, dev_id: u8, mode: CtrlMode) -> Result<(), BusError> {
        self.shared.setpoints.authority().mode_changing(dev_id);
        self.shared.setpoints.clear(Some(&[dev_id]));
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
        if matches!(param, ConfigParam::CtrlMode(_)) {
            self.shared.setpoints.authority().mode_changing(dev_id);
            self.shared.setpoints.clear(Some(&[dev_id]));
        }
        self.call(|reply| Request::WriteConfig {
            dev_id,
            param,
            reply,
        })
        .await
    }

    /// `param` to every device in `ids`: one frame to 0xFF when all run rev
    /// 2.0.8 (and the write has no reply), else one write each; every
    /// device verified for itself.
    pub async fn write_all(
        &self,
        ids: Vec<u8>,
        param: ConfigParam,
    ) -> Result<WriteAllOutcome, BusError> {
        self.call(|reply| Request::WriteAll { ids, param, reply })
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

/// Names the bus; the channels and watches behind a handle say nothing useful.
impl std::fmt::Debug for BusShared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BusShared")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl std::fmt::Debug for BusHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BusHandle")
            .field("bus", &self.name())
            .finish_non_exhaustive()
    }
}
