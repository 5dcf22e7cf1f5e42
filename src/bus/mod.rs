//! One owner per bus: a dedicated OS thread holds the port, schedules every
//! frame and publishes what it learns; the rest of the daemon uses a
//! [`handle::BusHandle`].
//!
//! Why a thread and not a tokio task: tokio's timer has millisecond
//! granularity, a frame at 500000 baud lasts 400 µs. The owner blocks in
//! `ppoll` with sub-millisecond timeouts and talks to the async world through
//! channels and watches.
//!
//! # Layout
//! One-way layers: each room imports only from the rooms listed above it.
//!
//! The contract and pure data:
//! - [`error`]: what went wrong, typed (`Timeout`, `Refused`, `UnexpectedReply`,
//!   `Down`, …); the HTTP status of each is chosen in the HTTP layer (`http::error`).
//! - [`firmware`]: which protocol revision each device speaks, and how the daemon knows.
//! - [`config`]: [`BusConfig`]: port, baud, expected ids, poll plan, timing, firmware.
//! - [`authority`]: who may move a joint: the motion epoch per joint, advanced by
//!   e-stop, disable, reset, fault, mode change and enable; stale commands are dropped.
//! - [`setpoints`]: the latest-value store of joint targets, each with its epoch.
//! - [`state`]: what the owner publishes: snapshot, counters, frame log, wire acks.
//! - [`events`]: what subscribers hear as it happens ([`events::BusEvent`]).
//! - [`loan`]: the port lent to a one-shot job (the doctor's checks of a running bus).
//! - [`handle`]: the cloneable handle and the requests it sends (the API's contract).
//! - [`motion`]: the joints following a move, sampled by the owner every control cycle.
//! - [`owed`]: current limits a routine could not give back yet; nothing new moves those joints.
//!
//! The pure parts the scheduler is made of:
//! - [`wire`]: the line model: when frames leave, when a reply is due or overdue.
//! - [`reply_lag`]: how long after the model replies reach the host (a low quantile).
//! - [`packets`]: which reply ended a full USB packet, and when the host read it.
//! - [`usb`]: behind a USB adapter, the polls written ahead (replies in flight), each
//!   write confirmed by the port's output count or bounded by a learnt guard.
//! - [`poll`]: control budget and poll plan.
//! - [`coalesce`]: pending setpoints → cheapest correct frames.
//! - [`registry`]: per-device state, online/offline, rates.
//! - [`verify`]: how each config write is confirmed.
//!
//! Decisions, then I/O:
//! - [`scheduler`]: what goes on the wire next: `next(now, work) -> Slot`,
//!   fed with what happened (pure, no I/O, no clock; unit-tested alone).
//! - `link`: the port: writes, reads, reply matching, frame log, reopen.
//! - `owner`: the thread: asks the scheduler, does the slot's I/O; its
//!   `ctx` (port + scheduler + publication) is all one-shot requests
//!   (`jobs`, `estop`, `scan`, `baud`, `start`) get to work with.

pub mod authority;
pub(crate) mod coalesce;
pub(crate) mod config;
pub mod error;
pub(crate) mod events;
pub mod firmware;
pub mod handle;
mod link;
pub mod loan;
pub mod motion;
pub mod owed;
mod owner;
mod packets;
pub(crate) mod poll;
pub(crate) mod registry;
mod reply_lag;
pub(crate) mod scheduler;
pub(crate) mod setpoints;
pub(crate) mod state;
pub mod usb;
pub(crate) mod verify;
pub(crate) mod wire;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

pub use config::{AdapterSetting, BusConfig, PollPlan, ShutdownState, StartPolicy, Timing};
pub use error::BusError;
pub use handle::{BusHandle, BusShared, BusSnapshot, Setpoint, Source, Targets};

use crate::transport::tty::tty_opener;
use crate::transport::Opener;
use crate::transport::Transport;
use link::Link;
use owner::Owner;

/// Prefix of every owner thread's name (`/proc/*/task/*/comm`), so tools
/// and the bench can find the daemon's bus threads.
pub const THREAD_PREFIX: &str = "bus-";
/// Linux keeps 15 bytes of a thread name.
const THREAD_NAME_MAX: usize = 15;

/// The running owner of one bus. Dropping it stops the owner too.
#[derive(Debug)]
pub struct BusThread {
    stop: Arc<AtomicBool>,
    join: Option<JoinHandle<()>>,
}

impl BusThread {
    /// Disables every device, closes the port and waits for the owner to end.
    pub fn stop(mut self) {
        self.halt();
    }

    /// True once the owner thread has ended.
    pub fn is_finished(&self) -> bool {
        self.join.as_ref().map_or(true, |j| j.is_finished())
    }

    fn halt(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(join) = self.join.take() {
            if join.join().is_err() {
                tracing::error!("bus owner thread panicked");
            }
        }
    }
}

impl Drop for BusThread {
    fn drop(&mut self) {
        self.halt();
    }
}

/// Starts the owner of a bus on a tty path. A port that cannot be opened
/// yet is not an error: the bus starts down and keeps retrying.
pub fn spawn_bus(cfg: BusConfig) -> Result<(BusHandle, BusThread), BusError> {
    let opener = tty_opener(cfg.path.clone(), cfg.rs485);
    spawn(cfg, None, Some(opener))
}

/// Starts the owner of a bus whose port `opener` opens (and reopens after
/// it was lost): a simulator's pty with its adapter model's count
/// (`SimHandle::pty_opener`). `cfg.path` only names the port then.
pub fn spawn_bus_with(cfg: BusConfig, opener: Opener) -> Result<(BusHandle, BusThread), BusError> {
    spawn(cfg, None, Some(opener))
}

/// Starts the owner of a bus on a transport handed in (an in-memory pipe in
/// tests). After a hang-up the same transport is probed until it works again.
pub fn spawn_bus_on(
    cfg: BusConfig,
    transport: Box<dyn Transport>,
) -> Result<(BusHandle, BusThread), BusError> {
    spawn(cfg, Some(transport), None)
}

fn spawn(
    cfg: BusConfig,
    port: Option<Box<dyn Transport>>,
    opener: Option<Opener>,
) -> Result<(BusHandle, BusThread), BusError> {
    cfg.validate()?;
    let path = cfg.path.display().to_string();
    let shared = BusShared::new(
        cfg.name.clone(),
        BusSnapshot::new(&cfg.name, &path, cfg.baud),
    );
    let (tx, rx) = std::sync::mpsc::sync_channel(handle::REQUEST_QUEUE_LEN);
    let stop = Arc::new(AtomicBool::new(false));
    let link = Link::new(port, opener, cfg.baud, &cfg.timing, shared.clone());
    let name = thread_name(&cfg.name);
    let owner = Owner::new(cfg, shared.clone(), rx, stop.clone(), link);
    let join = std::thread::Builder::new()
        .name(name)
        .spawn(move || owner.run())
        .map_err(|e| BusError::Down {
            bus: shared.name.clone(),
            reason: format!("cannot start the owner thread: {e}"),
        })?;
    let handle = BusHandle::new(shared, tx);
    Ok((
        handle,
        BusThread {
            stop,
            join: Some(join),
        },
    ))
}

fn thread_name(bus: &str) -> String {
    let mut name = format!("{THREAD_PREFIX}{bus}");
    while name.len() > THREAD_NAME_MAX {
        name.pop();
    }
    name
}
