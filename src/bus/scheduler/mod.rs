//! The bus's decisions, apart from its I/O: what goes on the wire next.
//!
//! A state machine in the spirit of rumqttc's `MqttState`: no port, no
//! thread, no clock of its own. The owner passes the time and the queued
//! work to [`Scheduler::next`] and gets a [`Slot`]; it does the I/O the slot
//! names and feeds back what happened (frames sent, replies, timeouts, the
//! port lost or reopened). The order of work, when the line is free:
//! e-stop, a queued one-shot request, the startup scan, setpoints (within
//! the control budget), a telemetry poll, setpoints again (when there is
//! nothing to poll), else listen.
//!
//! Its parts are the pure pieces beside it: the [`WireClock`] (when the line
//! frees, reply windows), the [`ControlBudget`] and [`PollPlanner`], the
//! coalescer (through `control`), the [`Registry`] and the reads whose
//! replies may still come late (`late`). This file chooses the slot; how a
//! free wire is filled is in `fill`, the e-stop's slot in `estop`, the
//! firmware probes in `firmware`, and what it hands a USB adapter's
//! pipeline and takes back in `usb`.

mod control;
mod estop;
mod fill;
mod firmware;
mod jobs;
mod late;
mod reopen;
mod replies;
#[cfg(test)]
mod tests;
mod usb;

use std::time::{Duration, Instant};

#[cfg(test)]
use crate::bus::coalesce::Pending;
use crate::bus::coalesce::Planned;
use crate::bus::config::{BusConfig, StartPolicy};
use crate::bus::events::BusEvent;
use crate::bus::firmware::FirmwarePolicy;
use crate::bus::poll::{ControlBudget, PollPlanner};
use crate::bus::registry::Registry;
use crate::bus::setpoints::SetpointStore;
use crate::bus::state::WireAck;
use crate::bus::usb::pipeline::UsbPipeline;
use crate::bus::wire::{ReplyWindow, WireClock};
use crate::protocol::InfoBlock;

use late::LateReplies;
#[cfg(test)]
use reopen::{BACKOFF_FIRST, BACKOFF_MAX, LISTEN_ON_OPEN};

/// Setpoint frames that may go out between two frames of a one-shot
/// request, so a long scan does not freeze the joints.
pub(crate) const MAX_INTERLEAVED: u32 = 2;

/// An e-stop is waiting: the request must give way before its next frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Preempted;

/// Control frames written in front of a poll on a latent adapter: the two
/// broadcasts of 16 joints.
pub(crate) const MAX_BATCHED: usize = 2;

/// Backed off (guarded or lockstep), control-only transfers before each poll. One without a poll
/// (two broadcasts, 0.8 ms) holds the wire one USB frame: late, it only
/// queues in the adapter's FIFO, with no reply to collide with. One with
/// a poll holds it 3 (1.7 ms of frames and reply, and the frame a late
/// write may slip). One of each: 2 control updates and 1 poll in 4
/// frames where the bound has 2 of each: control 1.0 of it, telemetry
/// 0.5. Every mix lies on control/2 + telemetry = 1 (none: 0.67 and
/// 0.67; two: 1.2 and 0.4): control keeps the bound, telemetry gives way.
pub(crate) const CONTROL_ONLY_PER_POLL: u32 = 1;

/// How long the owner listens when there is nothing to send. Bounds how
/// late it notices a request or setpoint on an idle bus.
pub(crate) const IDLE_TICK: Duration = Duration::from_millis(1);

/// What the owner does next.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Slot {
    /// Write nothing; listen (take unsolicited replies in) until `until`:
    /// the line is busy, the port was just opened, or there is nothing to do.
    Listen { until: Instant },
    /// Disable every device now (e-stop generation `generation`).
    EStop { generation: u64 },
    /// Run the queued one-shot request.
    Request,
    /// Scan the configured range (no ids were configured).
    Scan,
    /// Disable these joints, found enabled at start (`on_start = "disable"`):
    /// ahead of everything but an e-stop.
    Release { ids: Vec<u8> },
    /// Ask `dev_id` its firmware revision (an `INFO_07` read; silence is
    /// V2.0.1): once, when an `auto` device is first heard.
    Probe { dev_id: u8 },
    /// Write this control frame (coalesced setpoints).
    Control(Planned),
    /// Behind a USB adapter whose pipeline backed off (guarded or
    /// lockstep): these control frames in one write, without a poll.
    ControlBatch(Vec<Planned>),
    /// Read `block` of `dev_id`; its reply window follows from
    /// [`Scheduler::sent`] and [`Scheduler::reply_window`].
    Poll { dev_id: u8, block: InfoBlock },
    /// These control frames and then the poll in one write: behind a
    /// latent adapter (USB) one transfer instead of a round trip each; on
    /// a native line the control frame the budget makes a poll follow.
    Batch {
        control: Vec<Planned>,
        dev_id: u8,
        block: InfoBlock,
    },
    /// The port is down: try to open it at `at` (fail requests meanwhile).
    Reopen { at: Instant },
}

/// The work waiting outside the scheduler when it decides.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Work<'a> {
    /// The handle's e-stop counter (a press not yet served is above the
    /// generation the scheduler last handed out).
    pub estop_generation: u64,
    /// A one-shot request is waiting.
    pub request_queued: bool,
    /// The latest-value store of joint targets.
    pub setpoints: &'a SetpointStore,
}

/// Where a one-shot request stands (how its frames and setpoints interleave).
#[derive(Debug, Clone, Copy, Default)]
struct JobPhase {
    /// Frames the current request has written.
    frames: u32,
    /// Setpoint frames written since its last frame.
    interleaved: u32,
    /// Devices and port at different bauds: nothing may interrupt.
    exclusive: bool,
}

/// The decision state of one bus.
#[derive(Debug)]
pub(crate) struct Scheduler {
    clock: WireClock,
    reg: Registry,
    planner: PollPlanner,
    budget: ControlBudget,
    control: control::Control,
    reopen: reopen::Reopen,
    job: JobPhase,
    /// The last e-stop generation handed out as a slot.
    estop_seen: u64,
    /// The configured range still has to be scanned.
    needs_scan: bool,
    /// What to do with a joint found enabled at start.
    on_start: StartPolicy,
    /// Which devices are asked their firmware revision, which are told.
    firmware: FirmwarePolicy,
    /// Unanswered probes in a row that make a device V2.0.1 (1 + retries:
    /// as many tries as any read gets, so noise does not decide).
    probe_attempts: u32,
    /// The last slot was a probe: the next goes to the wire's usual work, so
    /// probing a bus of silent V2.0.1 devices never starves polls or setpoints.
    probed_last: bool,
    /// Joints found enabled and still to be disabled (`on_start = "disable"`).
    release: std::collections::BTreeSet<u8>,
    /// The reads that timed out or were given up, and when each reply was
    /// due: a reply may still come, late, and must not be taken for an
    /// announcement.
    late: LateReplies,
    /// What subscribers should hear at the next publication.
    events: Vec<BusEvent>,
    /// Setpoints dropped for ids nobody answers to, not yet counted.
    dropped: u64,
    /// Behind a latent (USB) adapter: the frame clock and the polls
    /// written blind (see [`crate::bus::usb::pipeline`]).
    pipeline: Option<UsbPipeline>,
    /// Writes that came too close to a USB frame boundary, not yet counted.
    ambiguous_writes: u64,
    /// How long a backed-off USB pipeline stays clean before stepping down.
    usb_recover: Duration,
    /// Changes of the USB pipeline's mode, for the owner to log and count.
    usb_changes: Vec<crate::bus::usb::guard::Change>,
    /// Control-only transfers since the last poll (backed off,
    /// [`CONTROL_ONLY_PER_POLL`] go between polls, if setpoints are pending).
    control_only: u32,
    /// The latest the control-only transfers since the last poll may end
    /// on the wire within the reach they were written under. Their hold
    /// leans on the next poll's, which queues behind them in the adapter;
    /// that poll may be written under a narrower reach once the guard has
    /// stepped down.
    queued_until: Option<Instant>,
    /// The port says when the adapter took a write (kept for a pipeline
    /// made anew when the adapter changes).
    port_confirms: bool,
}

impl Scheduler {
    /// A bus with its port not open yet (the first slot is `Reopen` now).
    pub(crate) fn new(cfg: &BusConfig, now: Instant) -> Self {
        let mut reg = Registry::new(&cfg.name, cfg.poll.offline_after);
        cfg.ids.iter().for_each(|id| reg.expect(*id));
        Self {
            clock: WireClock::new(cfg.baud, &cfg.timing, now),
            reg,
            planner: PollPlanner::new(
                cfg.poll.info01_every,
                Duration::from_millis(cfg.poll.offline_poll_ms),
            ),
            budget: ControlBudget::new(cfg.poll.control_share, cfg.frame_time(), now),
            control: control::Control::default(),
            reopen: reopen::Reopen::new(now),
            job: JobPhase::default(),
            estop_seen: 0,
            needs_scan: cfg.ids.is_empty(),
            on_start: cfg.on_start,
            // Checked when the config was loaded; a bus built in code with a
            // bad list asks every device rather than failing here.
            firmware: cfg.firmware_policy().unwrap_or_default(),
            probe_attempts: 1 + cfg.timing.retries,
            probed_last: false,
            release: Default::default(),
            late: LateReplies::default(),
            events: Vec::new(),
            dropped: 0,
            pipeline: None,
            ambiguous_writes: 0,
            usb_recover: Duration::from_millis(cfg.timing.usb_recover_ms),
            usb_changes: Vec::new(),
            control_only: 0,
            queued_until: None,
            port_confirms: false,
        }
    }

    /// The next slot at `now`.
    pub(crate) fn next(&mut self, now: Instant, work: &Work<'_>) -> Slot {
        if !self.reopen.is_up() {
            // A setpoint sent while the bus was down is stale when it comes back.
            self.control.drop_all(work.setpoints);
            if let Some(slot) = self.estop_slot(work) {
                return slot;
            }
            return Slot::Reopen {
                at: self.reopen.next_open(),
            };
        }
        // An e-stop does not wait for a write the adapter is overdue to
        // take: it can only queue behind it, and must not wait more.
        if self.confirmation_overdue() {
            if let Some(slot) = self.estop_slot(work) {
                return slot;
            }
        }
        let ready = self.write_at(now).max(self.reopen.quiet_until());
        if now < ready {
            return Slot::Listen { until: ready };
        }
        if let Some(slot) = self.estop_slot(work) {
            return slot;
        }
        if let Some(slot) = self.drain_first(now, work) {
            return slot;
        }
        if !self.release.is_empty() {
            self.control.clear_prepared();
            self.job = JobPhase::default();
            let ids = std::mem::take(&mut self.release).into_iter().collect();
            return Slot::Release { ids };
        }
        if work.request_queued || self.needs_scan {
            self.control.clear_prepared();
            self.job = JobPhase::default();
            return if work.request_queued {
                Slot::Request
            } else {
                Slot::Scan
            };
        }
        if !std::mem::take(&mut self.probed_last) {
            if let Some(dev_id) = self.firmware_to_ask() {
                self.control.clear_prepared();
                self.job = JobPhase::default();
                self.probed_last = true;
                return Slot::Probe { dev_id };
            }
        }
        self.wire_slot(now, work.setpoints)
    }

    /// When the next frame may be handed to the port: a little before the
    /// line frees; behind a USB adapter whose frame clock is known, in the
    /// middle of the USB frame before the boundary the line allows.
    /// Behind one whose clock is not known yet, once the line is free and
    /// the guard has passed: a write made earlier could leave while a
    /// reply is still on the wire.
    pub(crate) fn write_at(&self, now: Instant) -> Instant {
        match &self.pipeline {
            Some(pipeline) => pipeline.write_at(self.clock.free_at(), now),
            None => self.clock.write_at(),
        }
    }

    /// When the reply to a request ending at `end` is due and given up on.
    pub(crate) fn reply_window(&self, end: Instant) -> ReplyWindow {
        self.clock.reply_window(end)
    }

    /// The startup scan found what there is: no need to scan again.
    pub(crate) fn scan_done(&mut self) {
        self.needs_scan = false;
    }

    pub(crate) fn clock(&self) -> &WireClock {
        &self.clock
    }

    pub(crate) fn registry(&self) -> &Registry {
        &self.reg
    }

    pub(crate) fn registry_mut(&mut self) -> &mut Registry {
        &mut self.reg
    }

    /// Setpoints taken from the store and not yet on the wire.
    #[cfg(test)]
    pub(crate) fn pending(&self) -> &std::collections::BTreeMap<u8, Pending> {
        self.control.pending()
    }

    /// The wire ack to publish, if one came up since the last call.
    pub(crate) fn take_ack(&mut self) -> Option<WireAck> {
        self.control.take_ack()
    }

    /// Setpoints dropped (for ids no device answers to) since the last call.
    pub(crate) fn take_dropped(&mut self) -> u64 {
        std::mem::take(&mut self.dropped)
    }

    pub(crate) fn push_event(&mut self, event: BusEvent) {
        self.events.push(event);
    }

    pub(crate) fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The events to publish, oldest first.
    pub(crate) fn drain_events(&mut self) -> std::vec::Drain<'_, BusEvent> {
        self.events.drain(..)
    }

    /// Forgets pending setpoints and skips what the store holds now
    /// (e-stop, a bus that was down).
    pub(crate) fn drop_setpoints(&mut self, store: &SetpointStore) {
        self.control.drop_all(store);
    }

    /// One joint's pending setpoint is void (disabled, re-zeroed, mode changed).
    pub(crate) fn forget_setpoint(&mut self, id: u8) {
        self.control.forget(id);
    }

    /// After an id change the device's entry and pending setpoint follow it.
    pub(crate) fn rename(&mut self, old: u8, new: u8) {
        self.reg.rename(old, new);
        self.control.rename(old, new);
    }

    /// The port now runs at `baud`: frames take another time.
    pub(crate) fn set_baud(&mut self, baud: u32) {
        self.clock.set_baud(baud);
        self.budget.set_frame(self.clock.frame_time());
    }

    /// The adapter in front of the bus: reply deadlines follow it, and a
    /// latent one gets control frames and the next poll in one write.
    pub(crate) fn set_adapter(&mut self, adapter: crate::transport::adapter::AdapterModel) {
        self.clock.set_adapter(adapter);
        match (self.pipeline.as_mut(), adapter.usb_frame()) {
            (Some(pipeline), Some(period)) if pipeline.period() == period => {
                pipeline.set_adapter(adapter);
            }
            _ => {
                self.pipeline = UsbPipeline::for_adapter(adapter, self.usb_recover, Instant::now());
                if let Some(pipeline) = self.pipeline.as_mut() {
                    pipeline.set_port_confirms(self.port_confirms);
                }
            }
        }
    }
}
