//! The scheduler's side of a latent (USB) adapter: what it passes to and
//! takes from the [`UsbPipeline`] (write confirmation, the frame clock, the
//! polls in flight, when a write leaves the adapter), so the slot logic
//! beside it reads the same with or without one.

use std::time::{Duration, Instant};

use super::{Scheduler, Slot, Work, IDLE_TICK};
use crate::bus::events::BusEvent;
use crate::bus::usb::pipeline::{Inflight, UsbPipeline};
use crate::bus::wire::Want;

impl Scheduler {
    /// Whether the port just opened says when the adapter took a write
    /// ([`crate::transport::Transport::unsent`]): then writes are confirmed
    /// ([`crate::bus::usb::confirm`]).
    pub(crate) fn set_port_confirms(&mut self, on: bool) {
        self.port_confirms = on;
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.set_port_confirms(on);
        }
    }

    /// True while a write waits to be seen taken by the adapter: the owner
    /// reads the port's count for [`Self::confirm_writes`] before the next
    /// slot.
    pub(crate) fn awaiting_confirmation(&self) -> bool {
        self.pipeline
            .as_ref()
            .is_some_and(UsbPipeline::awaiting_confirmation)
    }

    pub(super) fn confirmation_overdue(&self) -> bool {
        self.pipeline
            .as_ref()
            .is_some_and(UsbPipeline::confirmation_overdue)
    }

    /// Confirmed writes seen taken late, and counts given up on, since the
    /// last call.
    pub(crate) fn take_confirm_counts(&mut self) -> (u64, u64) {
        self.pipeline
            .as_mut()
            .map_or((0, 0), UsbPipeline::take_confirm_counts)
    }

    /// A write waited for its reply (or its deadline): nothing waits to
    /// be seen taken.
    pub(crate) fn exchange_settled(&mut self) {
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.exchange_settled();
        }
    }

    /// The port's count of bytes the adapter has not taken read `unsent`
    /// at `now`: a write that left later than the wire model had moves
    /// the model (the line is held that much longer).
    pub(crate) fn confirm_writes(&mut self, unsent: Option<usize>, now: Instant) {
        let Some(pipeline) = self.pipeline.as_mut() else {
            return;
        };
        let (by, change) = pipeline.confirm(unsent, now);
        self.clock.hold_longer(by);
        self.usb_changed(change);
    }

    /// True when polls are written blind: behind any latent (USB)
    /// adapter, timed by its frame clock once that is known, each taken
    /// to leave as late as it may until then; not while the pipeline has
    /// backed off to `lockstep`.
    pub(crate) fn pipelining(&self) -> bool {
        self.pipeline.as_ref().is_some_and(|p| p.guard().blind())
    }

    /// The link's running total of garbled bytes (CRC errors and bytes
    /// skipped) is `total` at `now`; also steps a clean pipeline down.
    pub(crate) fn usb_watch(&mut self, total: u64, now: Instant) {
        let Some(pipeline) = self.pipeline.as_mut() else {
            return;
        };
        let guard = pipeline.guard_mut();
        let change = guard.garbled_total(total, now).or_else(|| guard.tick(now));
        self.usb_changed(change);
    }

    pub(super) fn usb_changed(&mut self, change: Option<crate::bus::usb::guard::Change>) {
        let Some(change) = change else {
            return;
        };
        let guard = self.pipeline.as_ref().map(|p| p.guard().reach());
        self.events.push(BusEvent::UsbPipeline {
            bus: self.reg.bus().to_string(),
            mode: change.to.as_str(),
            previous: change.from.as_str(),
            guard_us: guard.map_or(0, |g| g.as_micros() as u64),
            reason: change.reason.clone(),
        });
        self.usb_changes.push(change);
    }

    /// Sentinels answered, and late, since the last call.
    pub(crate) fn take_sentinel_counts(&mut self) -> (u64, u64) {
        self.pipeline
            .as_mut()
            .map_or((0, 0), |p| p.guard_mut().take_sentinel_counts())
    }

    /// Changes of the pipeline's mode since the last call.
    pub(crate) fn take_usb_changes(&mut self) -> Vec<crate::bus::usb::guard::Change> {
        std::mem::take(&mut self.usb_changes)
    }

    /// The USB pipeline as the bus view shows it (behind a latent adapter).
    pub(crate) fn usb_view(
        &mut self,
        now: Instant,
    ) -> Option<crate::bus::usb::guard::UsbPipelineView> {
        let pipeline = self.pipeline.as_mut()?;
        let period = pipeline.period();
        let confirming = pipeline.confirming();
        let (late, gave_up) = pipeline.confirm_counts();
        let mut view = pipeline.guard_mut().view(period, now);
        view.confirming = confirming;
        view.writes_taken_late = late;
        view.counts_given_up = gave_up;
        view.arrival_lag_us = pipeline.arrival_lag().as_micros() as u64;
        Some(view)
    }

    /// True once the USB frame clock is known from reply arrivals (writes
    /// are then aimed at its boundaries).
    pub(crate) fn usb_clock_known(&self) -> bool {
        self.pipeline.as_ref().is_some_and(UsbPipeline::active)
    }

    /// The port woke the owner with bytes at `at`: behind a USB adapter,
    /// one more sample of the frame clock.
    pub(crate) fn arrival(&mut self, at: Instant) {
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.arrival(at);
        }
    }

    /// How late the host sees the bytes an adapter hands over
    /// ([`UsbPipeline::set_arrival_lag`]).
    pub(crate) fn set_arrival_lag(&mut self, lag: Duration) {
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.set_arrival_lag(lag);
        }
    }

    /// A poll written blind (its request's last byte due on the wire at
    /// `end`): its reply is matched when it comes; the line is held for it.
    /// `handed` is when the write was handed to the port, `read_before`
    /// how many bytes had been read when it began ([`Inflight::read_before`]).
    pub(crate) fn track(
        &mut self,
        want: Want,
        end: Instant,
        (handed, read_before): (Instant, u64),
    ) {
        let window = self.clock.reply_window(end);
        let (wire_end, out) = self.reply_out(end);
        let frame = self.clock.frame_time();
        self.clock.reply_on_wire(end);
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.track(want, window, (handed, read_before), out, (wire_end, frame));
        }
    }

    /// When the reply to a request ending at `end` leaves the wire, and
    /// when it leaves the adapter: held until its latency timer, if it has
    /// one, has run from the reply's bytes (taken from the last: the latest).
    pub(super) fn reply_out(&self, end: Instant) -> (Instant, Instant) {
        let timer = self.clock.adapter().latency_timer().unwrap_or_default();
        let wire_end = self.clock.reply_end(end);
        (wire_end, wire_end + timer)
    }

    /// Behind a USB adapter, a reply waited for (lockstep, or a one-shot
    /// request) to a write handed over at `handed`, its request ending at
    /// `end`, was read at `at`: a write a frame late is seen as a blind
    /// poll's is.
    pub(crate) fn waited_reply(&mut self, end: Instant, handed: Instant, at: Instant) {
        let (_, out) = self.reply_out(end);
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.waited_reply(handed, out, at);
        }
    }

    /// The poll in flight `reply` answers, taken out; `followed_by`
    /// replies of the same device and block were read after it in the same
    /// batch, and its first byte was byte `first_byte` read since the port
    /// opened ([`UsbPipeline::take`]).
    pub(crate) fn take_inflight(
        &mut self,
        reply: &crate::protocol::Reply,
        followed_by: usize,
        first_byte: u64,
    ) -> Option<Inflight> {
        let want = Want {
            dev_id: reply.dev_id,
            index: reply.index,
        };
        self.pipeline.as_mut()?.take(want, followed_by, first_byte)
    }

    /// Polls in flight whose deadline passed by `now`, taken out.
    pub(crate) fn expired_inflight(&mut self, now: Instant) -> Vec<Inflight> {
        self.pipeline
            .as_mut()
            .map(|p| p.expired(now))
            .unwrap_or_default()
    }

    /// Polls in flight now.
    pub(crate) fn in_flight(&self) -> usize {
        self.pipeline.as_ref().map_or(0, UsbPipeline::in_flight)
    }

    /// `n` host frames were handed to the port at `handed`; returns when the
    /// last one's last byte leaves the wire.
    /// Behind a USB adapter with a known frame clock they leave at the
    /// boundary after the write (the later one when the write came close
    /// to one: counted in `ambiguous`).
    /// Before the clock is known, a write is taken to leave as late as it
    /// may: a period and the write's reach after it was made.
    pub(crate) fn sent(&mut self, handed: Instant, n: u32) -> Instant {
        self.sent_held(handed, n, true)
    }

    /// [`Self::sent`] for a write that asks no reply (control frames
    /// only): behind a backed-off USB pipeline held a frame less than a
    /// poll's (see [`UsbPipeline::release_without_reply`]).
    pub(crate) fn sent_without_reply(&mut self, handed: Instant, n: u32) -> Instant {
        self.sent_held(handed, n, false)
    }

    fn sent_held(&mut self, handed: Instant, n: u32, asks_reply: bool) -> Instant {
        let Some(pipeline) = self.pipeline.as_mut() else {
            return self.clock.host_frames(handed, n);
        };
        let released = if asks_reply {
            let mut released = pipeline.latest_release(handed);
            if let Some(queued) = self.queued_until.take() {
                released.at = released.at.max(queued);
            }
            released
        } else {
            let latest = pipeline.latest_release(handed).at + self.clock.frame_time() * n;
            self.queued_until = Some(self.queued_until.map_or(latest, |q| q.max(latest)));
            pipeline.release_without_reply(handed)
        };
        self.ambiguous_writes += u64::from(released.ambiguous);
        pipeline.written(handed);
        self.clock.host_frames(released.at, n)
    }

    /// Writes that came too close to a USB frame boundary to know which
    /// frame took them, since the last call.
    pub(crate) fn take_ambiguous_writes(&mut self) -> u64 {
        std::mem::take(&mut self.ambiguous_writes)
    }

    /// With polls in flight, a one-shot request, a scan, a release or a
    /// probe waits for them (their replies, or their deadlines): those
    /// transactions wait for each reply, and a reply still in the adapter
    /// must not be taken for theirs. An e-stop does not wait.
    pub(super) fn drain_first(&self, now: Instant, work: &Work<'_>) -> Option<Slot> {
        let deadline = self.pipeline.as_ref()?.next_deadline()?;
        let other_work = work.request_queued
            || self.needs_scan
            || !self.release.is_empty()
            || (!self.probed_last && self.probe_wanted());
        other_work.then(|| Slot::Listen {
            until: deadline.min(now + IDLE_TICK),
        })
    }
}
