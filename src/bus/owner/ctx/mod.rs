//! What the owner's code works with, in one place: the port ([`Link`]),
//! the [`Scheduler`], the shared state it publishes to, and the request
//! queue. One-shot requests get a `&mut Ctx` and use its methods: they
//! never see its fields.
//!
//! - `io`: the wire primitives: listening, frames out, transactions.
//! - `port`: the port lost and reopened, the bus down.
//! - `publish`: rates and the snapshot.

mod io;
mod port;
mod publish;

use std::sync::atomic::Ordering;
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::config::BusConfig;
use crate::bus::error::BusError;
use crate::bus::handle::{BusCounters, BusEvent, BusShared, LinkState, Request};
use crate::bus::link::Link;
use crate::bus::scheduler::{Scheduler, Slot, Work};
use crate::bus::setpoints::SetpointStore;

use super::stats::Stats;

pub(crate) struct Ctx {
    cfg: BusConfig,
    shared: Arc<BusShared>,
    requests: Receiver<Request>,
    link: Link,
    /// Every decision: what goes on the wire next.
    sched: Scheduler,
    stats: Stats,
    link_state: LinkState,
    /// The port was open at least once: something on it may be enabled.
    ever_up: bool,
    port_notes: Vec<String>,
    /// The adapter the bus plans for and how it was found, once the port
    /// reported one.
    adapter_info: Option<crate::transport::adapter::AdapterInfo>,
    /// Set when the owner is to stop ([`crate::bus::BusThread::stop`]).
    stopping: Arc<std::sync::atomic::AtomicBool>,
    /// What starting the thread found worth telling (no real-time priority).
    thread_notes: Vec<String>,
    /// A request taken from the queue, waiting for its slot.
    held: Option<Request>,
    /// When moves are sampled next.
    next_motion_sample: Instant,
    /// How long after the model replies reach this thread: it aims its
    /// wake-up and its watch of the port there.
    reply_lag: crate::bus::reply_lag::ReplyLag,
}

impl Ctx {
    pub(crate) fn new(
        cfg: BusConfig,
        shared: Arc<BusShared>,
        requests: Receiver<Request>,
        link: Link,
        stopping: Arc<std::sync::atomic::AtomicBool>,
    ) -> Self {
        let now = Instant::now();
        Self {
            sched: Scheduler::new(&cfg, now),
            stats: Stats::new(Duration::from_millis(cfg.poll.snapshot_ms), now),
            cfg,
            shared,
            requests,
            link,
            link_state: LinkState::Opening,
            ever_up: false,
            port_notes: Vec::new(),
            adapter_info: None,
            stopping,
            thread_notes: Vec::new(),
            held: None,
            next_motion_sample: now,
            reply_lag: crate::bus::reply_lag::ReplyLag::default(),
        }
    }

    /// Asks the scheduler for the next slot at `now`.
    pub(crate) fn decide(&mut self, now: Instant) -> Slot {
        self.expire_inflight(now);
        self.sample_moves(now);
        if self.held.is_none() && self.sched.link_is_up() {
            self.held = self.next_request();
        }
        self.look_at_count();
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
        slot
    }

    /// The flag that stops the owner.
    pub(crate) fn stopping(&self) -> Arc<std::sync::atomic::AtomicBool> {
        self.stopping.clone()
    }

    /// The port was open at least once since the owner started.
    pub(crate) fn ever_up(&self) -> bool {
        self.ever_up
    }

    /// While a write waits to be seen taken, reads the port's count for it
    /// ([`crate::bus::usb::confirm`]).
    pub(crate) fn look_at_count(&mut self) {
        if self.sched.awaiting_confirmation() {
            // Timed after the read: a count seen at 0 says the write was
            // taken by then, never earlier.
            let unsent = self.link.unsent();
            self.sched.confirm_writes(unsent, Instant::now());
        }
    }

    /// Joints following a move get their position at the instant the next
    /// control frame would reach the wire: every control cycle, at most
    /// once a frame time.
    fn sample_moves(&mut self, now: Instant) {
        if !self.shared.motion.is_active() || now < self.next_motion_sample {
            return;
        }
        let frame = self.sched.clock().frame_time();
        self.next_motion_sample = now + frame.min(crate::bus::motion::MIN_SAMPLE_INTERVAL);
        let wire_at = self.sched.write_at(now).max(now) + frame;
        let mut events = Vec::new();
        self.shared.motion.tick(
            wire_at,
            &self.shared.setpoints,
            self.sched.registry(),
            &mut events,
        );
        for event in events {
            self.sched.push_event(event);
        }
    }

    /// What a decision left to hand on: a wire ack, dropped setpoints.
    fn after_decision(&mut self) {
        self.link.counters.setpoints_dropped += self.sched.take_dropped();
        self.link.counters.setpoints_stale = self.shared.setpoints.authority().stale_dropped();
        if let Some(ack) = self.sched.take_ack() {
            self.shared.wire_acks.send_replace(ack);
        }
    }

    pub(crate) fn cfg(&self) -> &BusConfig {
        &self.cfg
    }

    pub(crate) fn name(&self) -> &str {
        &self.cfg.name
    }

    pub(crate) fn sched(&self) -> &Scheduler {
        &self.sched
    }

    pub(crate) fn sched_mut(&mut self) -> &mut Scheduler {
        &mut self.sched
    }

    /// The latest-value store of joint targets (shared with the handles).
    pub(crate) fn setpoints(&self) -> &SetpointStore {
        &self.shared.setpoints
    }

    pub(crate) fn shared(&self) -> &Arc<BusShared> {
        &self.shared
    }

    pub(crate) fn counters(&mut self) -> &mut BusCounters {
        &mut self.link.counters
    }

    pub(crate) fn push_event(&mut self, event: BusEvent) {
        self.sched.push_event(event);
    }

    /// Something about this thread subscribers should read in the snapshot.
    pub(crate) fn note_thread(&mut self, note: String) {
        self.thread_notes.push(note);
    }

    pub(crate) fn estop_generation(&self) -> u64 {
        self.shared.estop_generation.load(Ordering::SeqCst)
    }

    pub(crate) fn estop_pending(&self) -> bool {
        self.sched.estop_pending(self.estop_generation())
    }

    /// The request the scheduler gave a [`Slot::Request`] for.
    pub(crate) fn take_held(&mut self) -> Option<Request> {
        self.held.take()
    }

    fn next_request(&mut self) -> Option<Request> {
        let req = self.requests.try_recv().ok()?;
        self.shared.queued.fetch_sub(1, Ordering::Relaxed);
        self.link.counters.requests_queued += 1;
        Some(req)
    }

    /// Fails every queued request with `err` (the held one first); returns how many.
    pub(crate) fn fail_queued(&mut self, err: &BusError) -> u32 {
        let mut n = 0;
        while let Some(req) = self.held.take().or_else(|| self.next_request()) {
            req.fail(err.clone());
            n += 1;
        }
        n
    }

    /// Closes the port for good (the owner stops).
    pub(crate) fn close(&mut self) {
        self.link.close();
        self.link_state = LinkState::Down {
            reason: "stopped".into(),
            retry_in_ms: 0,
        };
    }
}
