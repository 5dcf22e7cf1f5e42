//! The bus owner: one OS thread per bus and the only code that touches its
//! port. Each time the line can take a frame it picks, in this order:
//! e-stop, a queued one-shot request, setpoints (within the control budget),
//! a telemetry poll, setpoints again (when there is nothing to poll).
//! While a reply is due nothing else is written.
//!
//! A lost port marks the bus down and every device offline; the owner then
//! retries with backoff, failing requests with `Down` meanwhile, and resumes
//! when the port is back. Nothing here can take another bus down.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::Instant;

use super::config::BusConfig;
use super::error::BusError;
use super::handle::{BusShared, LinkState, Request};
use super::link::Link;
use super::scheduler::{Scheduler, Slot, Work};
use super::stats::Stats;
use crate::rt::{precise_timers, set_fifo};

pub(super) struct Owner {
    pub(super) cfg: BusConfig,
    pub(super) shared: Arc<BusShared>,
    pub(super) requests: Receiver<Request>,
    stop: Arc<AtomicBool>,
    pub(super) link: Link,
    /// Every decision: what goes on the wire next.
    pub(super) sched: Scheduler,
    pub(super) stats: Stats,
    pub(super) link_state: LinkState,
    pub(super) port_notes: Vec<String>,
    /// What starting the thread found worth telling (no real-time priority).
    pub(super) thread_notes: Vec<String>,
    /// A request taken from the queue, waiting for its slot.
    held: Option<Request>,
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
        Self {
            sched: Scheduler::new(&cfg, now),
            stats: Stats::new(std::time::Duration::from_millis(cfg.poll.snapshot_ms), now),
            cfg,
            shared,
            requests,
            stop,
            link,
            link_state: LinkState::Opening,
            port_notes: Vec::new(),
            thread_notes: Vec::new(),
            held: None,
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
            let step = catch_unwind(AssertUnwindSafe(|| self.turn()));
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
        self.sched.job_abort();
        let err = self.lost(std::io::Error::other(format!("internal error: {what}")));
        // An e-stop cut short says so now rather than at its caller's timeout.
        let answered = self.shared.estop_done.borrow().0;
        let seen = self.sched.estop_seen();
        if seen > answered {
            self.shared.estop_done.send_replace((seen, Some(Err(err))));
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

    /// Asks the scheduler for the next slot and does what it names.
    fn turn(&mut self) {
        let now = Instant::now();
        if self.held.is_none() && self.sched.link_is_up() {
            self.held = self.next_request();
        }
        let work = Work {
            estop_generation: self.estop_generation(),
            request_queued: self.held.is_some(),
            setpoints: &self.shared.setpoints,
        };
        let slot = self.sched.next(now, &work);
        self.after_decision();
        // Bookkeeping goes where the line leaves slack, not between a reply
        // and the next frame (unless it has waited too long).
        if matches!(slot, Slot::Listen { .. }) || self.stats.overdue(now) {
            self.housekeeping(now);
        }
        self.do_slot(slot, now);
    }

    /// Errors have already marked the bus down; the next slot says so.
    fn do_slot(&mut self, slot: Slot, now: Instant) {
        let _ = match slot {
            Slot::Listen { until } => self.wait_until(until),
            Slot::Control(frame) => self.send_planned(frame),
            Slot::Poll { dev_id, block } => self.poll(dev_id, block),
            Slot::EStop { generation } => {
                self.estop(generation);
                Ok(())
            }
            Slot::Request => {
                if let Some(req) = self.held.take() {
                    self.run_request(req);
                }
                Ok(())
            }
            Slot::Scan => {
                self.startup_scan();
                Ok(())
            }
            Slot::Reopen { at } => {
                self.while_down(now, at);
                Ok(())
            }
        };
    }

    /// What a decision left to hand on: a wire ack, dropped setpoints.
    pub(super) fn after_decision(&mut self) {
        self.link.counters.setpoints_dropped += self.sched.take_dropped();
        if let Some(ack) = self.sched.take_ack() {
            self.shared.wire_acks.send_replace(ack);
        }
    }

    pub(super) fn estop_generation(&self) -> u64 {
        self.shared.estop_generation.load(Ordering::SeqCst)
    }

    pub(super) fn estop_pending(&self) -> bool {
        self.sched.estop_pending(self.estop_generation())
    }

    /// A request taken from the queue (the held one first).
    pub(super) fn take_request(&mut self) -> Option<Request> {
        self.held.take().or_else(|| self.next_request())
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
        while let Some(req) = self.take_request() {
            super::jobs::fail(req, err.clone());
            n += 1;
        }
        n
    }

    /// Brings the joints to the configured safe state and closes the port.
    fn shutdown(&mut self) {
        let disable = self.cfg.on_shutdown == super::config::ShutdownState::Disable;
        if disable && self.disable_everything().is_ok() {
            // Let the disable frames leave the wire before the port closes.
            let _ = self.wait_until(self.sched.clock().free_at());
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
