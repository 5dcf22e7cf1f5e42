//! The bus owner: one OS thread per bus and the only code that touches its
//! port. Each time the line can take a frame it picks, in this order:
//! e-stop, a queued one-shot request, setpoints (within the control budget),
//! a telemetry poll, setpoints again (when there is nothing to poll).
//! While a reply is due nothing else is written.
//!
//! A lost port marks the bus down and every device offline; the owner then
//! retries with backoff, failing requests with `Down` meanwhile, and resumes
//! when the port is back. Nothing here can take another bus down.

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::coalesce::Pending;
use super::config::BusConfig;
use super::error::BusError;
use super::handle::{BusEvent, BusShared, LinkState, Request};
use super::link::Link;
use super::poll::{ControlBudget, PollPlanner};
use super::recovery::BACKOFF_FIRST;
use super::registry::Registry;
use super::stats::Stats;
use crate::rt::{precise_timers, set_fifo};

/// How long the owner listens when there is nothing to send. Bounds how
/// late it notices a request or setpoint on an idle bus.
const IDLE_TICK: Duration = Duration::from_millis(1);

pub(super) struct Owner {
    pub(super) cfg: BusConfig,
    pub(super) shared: Arc<BusShared>,
    pub(super) requests: Receiver<Request>,
    stop: Arc<AtomicBool>,
    pub(super) link: Link,
    pub(super) reg: Registry,
    pub(super) planner: PollPlanner,
    pub(super) budget: ControlBudget,
    /// Setpoints taken from the store and not yet on the wire.
    pub(super) pending: BTreeMap<u8, Pending>,
    /// Highest store sequence number taken into `pending`.
    pub(super) seen_seq: u64,
    pub(super) acked_seq: u64,
    pub(super) estop_seen: u64,
    pub(super) events: Vec<BusEvent>,
    pub(super) stats: Stats,
    pub(super) link_state: LinkState,
    pub(super) port_notes: Vec<String>,
    /// What starting the thread found worth telling (no real-time priority).
    pub(super) thread_notes: Vec<String>,
    /// A control frame planned while a reply was on the wire, and the store
    /// sequence number it was planned at.
    pub(super) prepared: Option<(super::coalesce::Planned, u64)>,
    /// The configured range still has to be scanned (no expected ids given).
    pub(super) needs_scan: bool,
    /// Frames the current one-shot request has written (setpoints may
    /// interleave after its first).
    pub(super) job_frames: u32,
    /// The request is in a phase nothing may interrupt: devices and port at
    /// different bauds, where an e-stop's frames would not reach everyone.
    pub(super) exclusive: bool,
    /// The last read that timed out and when its reply was due: the reply
    /// may still come, late, and must not be taken for an announcement.
    pub(super) overdue: Option<(super::link::Want, Instant)>,
    pub(super) backoff: Duration,
    pub(super) next_open: Instant,
    pub(super) ever_up: bool,
}

impl Owner {
    pub(super) fn new(
        cfg: BusConfig,
        shared: Arc<BusShared>,
        requests: Receiver<Request>,
        stop: Arc<AtomicBool>,
        link: Link,
    ) -> Self {
        let now = Instant::now();
        let mut reg = Registry::new(&cfg.name, cfg.poll.offline_after);
        cfg.ids.iter().for_each(|id| reg.expect(*id));
        Self {
            planner: PollPlanner::new(
                cfg.poll.info01_every,
                Duration::from_millis(cfg.poll.offline_poll_ms),
            ),
            budget: ControlBudget::new(cfg.poll.control_share, cfg.frame_time(), now),
            stats: Stats::new(Duration::from_millis(cfg.poll.snapshot_ms), now),
            needs_scan: cfg.ids.is_empty(),
            cfg,
            shared,
            requests,
            stop,
            link,
            reg,
            pending: BTreeMap::new(),
            seen_seq: 0,
            acked_seq: 0,
            estop_seen: 0,
            events: Vec::new(),
            link_state: LinkState::Opening,
            port_notes: Vec::new(),
            thread_notes: Vec::new(),
            job_frames: 0,
            exclusive: false,
            overdue: None,
            prepared: None,
            backoff: BACKOFF_FIRST,
            next_open: now,
            ever_up: false,
        }
    }

    /// The thread's body: runs until [`super::BusThread::stop`].
    pub(super) fn run(mut self) {
        precise_timers();
        self.realtime();
        while !self.stop.load(Ordering::Acquire) {
            // A bug must not leave the joints with a dead owner and a stale
            // "up" snapshot: the owner catches it and starts over like after
            // an unplug (its state is rebuilt from the wire).
            let step = catch_unwind(AssertUnwindSafe(|| {
                if self.link.is_up() {
                    self.turn();
                } else {
                    self.while_down();
                }
            }));
            if let Err(panic) = step {
                self.recover_from_panic(panic.as_ref());
            }
        }
        self.shutdown();
    }

    fn recover_from_panic(&mut self, panic: &(dyn std::any::Any + Send)) {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        tracing::error!(bus = %self.cfg.name, "bus owner caught a panic ({what}); reopening the port");
        self.link.counters.owner_panics += 1;
        self.exclusive = false;
        self.job_frames = 0;
        let err = self.lost(std::io::Error::other(format!("internal error: {what}")));
        // An e-stop cut short says so now rather than at its caller's timeout.
        let answered = self.shared.estop_done.borrow().0;
        if self.estop_seen > answered {
            self.shared
                .estop_done
                .send_replace((self.estop_seen, Some(Err(err))));
        }
        self.publish(Instant::now());
    }

    fn realtime(&mut self) {
        let priority = self.cfg.timing.rt_priority;
        if priority == 0 {
            return;
        }
        if let Err(e) = set_fifo(0, priority) {
            let note = format!(
                "real-time priority {priority} refused ({e}): replies wait for the CPU under load"
            );
            tracing::info!(bus = %self.cfg.name, "{note}");
            self.thread_notes.push(note);
        }
    }

    /// One decision at the moment the line can take the next host frame.
    fn turn(&mut self) {
        // Bookkeeping goes where the line leaves slack, not between a reply
        // and the next frame (unless it has waited too long).
        let (now, write_at) = (Instant::now(), self.link.clock.write_at());
        if write_at > now || self.stats.overdue(now) {
            self.housekeeping(now);
        }
        if self.wait_until(write_at).is_err() {
            return;
        }
        if self.estop_pending() || self.needs_scan {
            self.prepared = None;
        }
        if self.estop_pending() {
            return self.estop();
        }
        if let Some(req) = self.next_request() {
            self.prepared = None;
            return self.run_request(req);
        }
        if self.needs_scan {
            return self.startup_scan();
        }
        // Errors have already marked the bus down; the loop sees it.
        let _ = self.schedule_wire(Instant::now());
    }

    /// Setpoints within budget, else a poll, else setpoints, else listen.
    fn schedule_wire(&mut self, now: Instant) -> Result<(), BusError> {
        let sent_prepared =
            self.prepared.is_some() && self.budget.allows(now) && self.send_control()?;
        // A prepared frame is good for this decision only.
        self.prepared = None;
        if sent_prepared {
            return Ok(());
        }
        self.collect_setpoints();
        if !self.pending.is_empty() && self.budget.allows(now) && self.send_control()? {
            return Ok(());
        }
        if self.poll_once()? || self.send_control()? {
            return Ok(());
        }
        self.wait_until(now + IDLE_TICK)
    }

    pub(super) fn estop_pending(&self) -> bool {
        self.shared.estop_generation.load(Ordering::SeqCst) > self.estop_seen
    }

    fn next_request(&mut self) -> Option<Request> {
        let req = self.requests.try_recv().ok()?;
        self.shared.queued.fetch_sub(1, Ordering::Relaxed);
        self.link.counters.requests_queued += 1;
        Some(req)
    }

    /// Fails every queued request with `err`; returns how many.
    pub(super) fn fail_queued(&mut self, err: &BusError) -> u32 {
        let mut n = 0;
        while let Some(req) = self.next_request() {
            super::jobs::fail(req, err.clone());
            n += 1;
        }
        n
    }

    /// Forgets pending setpoints and skips what the store holds now.
    pub(super) fn drop_setpoints(&mut self) {
        self.prepared = None;
        self.collect_setpoints();
        self.pending.clear();
        self.acked_seq = self.seen_seq;
    }

    /// Brings the joints to the configured safe state and closes the port.
    fn shutdown(&mut self) {
        let disable = self.cfg.on_shutdown == super::config::ShutdownState::Disable;
        if disable && self.disable_everything().is_ok() {
            // Let the disable frames leave the wire before the port closes.
            let _ = self.wait_until(self.link.clock.free_at());
        }
        if !disable {
            tracing::warn!(bus = %self.cfg.name, "stopping with the joints left enabled (on_shutdown = \"hold\")");
        }
        self.fail_queued(&BusError::Stopped);
        self.link.close();
        self.link_state = LinkState::Down {
            reason: "stopped".into(),
            retry_in_ms: 0,
        };
        self.publish(Instant::now());
    }
}
