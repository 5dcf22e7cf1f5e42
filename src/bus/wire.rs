//! The owner's model of the half-duplex line: when its last host frame leaves
//! the wire, when the next one should be handed to the port, and when a reply
//! is overdue.
//!
//! The port cannot tell us (a pty ignores the baud; a USB adapter's write
//! returns before the bytes leave the UART), so the owner paces by this model:
//! a frame handed over at `now` leaves the wire at
//! `max(now, free_at) + 200/baud` (SPEC §1). Pure: driven by the instants
//! the caller passes, so it is tested without threads.

use std::time::{Duration, Instant};

use super::config::{frame_time, Timing};
use crate::transport::adapter::AdapterModel;

/// The reply a transaction waits for: matched by device id and index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Want {
    pub dev_id: u8,
    pub index: u8,
}

/// When the reply to a request is expected (`due`, the model) and when it
/// counts as missing (`deadline`, the model plus margins).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ReplyWindow {
    pub due: Instant,
    pub deadline: Instant,
}

/// The line as the owner believes it to be.
#[derive(Debug, Clone)]
pub(crate) struct WireClock {
    frame: Duration,
    turnaround: Duration,
    reply_margin: Duration,
    lead: Duration,
    /// When the last host frame handed to the port leaves the wire.
    free_at: Instant,
    /// The largest lateness of a reply against the model seen lately
    /// (decaying), and when it was seen: the host path's own latency.
    late: Duration,
    late_at: Instant,
    /// The USB adapter in between: how long it holds a write and a reply.
    adapter: AdapterModel,
}

/// Half-life of the observed reply lateness: a stall seen once keeps the
/// deadline wide for minutes, since such stalls come back.
const LATE_HALF_LIFE_S: f64 = 60.0;
/// The deadline allows this many times the lateness seen.
const LATE_FACTOR: u32 = 2;
/// Bound on what observed lateness adds to the deadline: nothing else may
/// be written while a reply is due, so a long wait for a missing device
/// holds every joint's setpoints back.
const MAX_LATE_ALLOWANCE: Duration = Duration::from_millis(20);

impl WireClock {
    pub(crate) fn new(baud: u32, timing: &Timing, now: Instant) -> Self {
        Self {
            frame: frame_time(baud),
            turnaround: Duration::from_micros(timing.turnaround_us),
            reply_margin: Duration::from_micros(timing.reply_margin_us),
            lead: Duration::from_micros(timing.write_lead_us),
            free_at: now,
            late: Duration::ZERO,
            late_at: now,
            adapter: AdapterModel::Native,
        }
    }

    /// The adapter the port turned out to be (or the config says).
    pub(crate) fn set_adapter(&mut self, adapter: AdapterModel) {
        self.adapter = adapter;
    }

    pub(crate) fn adapter(&self) -> AdapterModel {
        self.adapter
    }

    /// One poll as the host lives it on this adapter: the write's wait for
    /// a USB frame, request and reply on the wire, the adapter's hold.
    pub(crate) fn transaction_time(&self) -> Duration {
        self.transaction_time_with(self.adapter)
    }

    /// [`Self::transaction_time`] on another adapter (what a fix would give).
    pub(crate) fn transaction_time_with(&self, adapter: AdapterModel) -> Duration {
        adapter.write_hold() + self.frame * 2 + self.turnaround + adapter.reply_hold()
    }

    /// After a baud change: frames take another time from now on.
    pub(crate) fn set_baud(&mut self, baud: u32) {
        self.frame = frame_time(baud);
    }

    pub(crate) fn frame_time(&self) -> Duration {
        self.frame
    }

    /// When the line is free of every host frame handed over so far.
    pub(crate) fn free_at(&self) -> Instant {
        self.free_at
    }

    /// When to hand the next host frame to the port: a little before the line
    /// frees, so the port's queue never runs dry, yet as late as possible so
    /// the frame carries the freshest setpoints.
    ///
    /// The lead stays below ¾ of a frame time, so at most one frame waits in
    /// the port's queue and an e-stop is never behind more than one frame.
    pub(crate) fn write_at(&self) -> Instant {
        let lead = self.lead.min(self.frame * 3 / 4);
        self.free_at.checked_sub(lead).unwrap_or(self.free_at)
    }

    /// Accounts `n` host frames handed to the port at `now`; returns when the
    /// last byte of the last one leaves the wire.
    pub(crate) fn host_frames(&mut self, now: Instant, n: u32) -> Instant {
        self.free_at = self.free_at.max(now) + self.frame * n;
        self.free_at
    }

    /// When the last byte of a reply to a request ending at `request_end`
    /// leaves the wire.
    pub(crate) fn reply_end(&self, request_end: Instant) -> Instant {
        request_end + self.turnaround + self.frame
    }

    /// When a reply to a request ending at `request_end` should reach the
    /// host: its end on the wire, then the adapter's hold (its latency
    /// timer, or one USB frame; nothing on a pty).
    pub(crate) fn reply_due(&self, request_end: Instant) -> Instant {
        request_end + self.turnaround + self.frame + self.adapter.reply_hold()
    }

    /// The latest a reply to a request ending at `request_end` may
    /// complete: the model, the configured margin, and twice the lateness
    /// the host path has shown lately (like TCP's retransmission timeout,
    /// the allowance follows what is measured).
    pub(crate) fn reply_deadline(&self, request_end: Instant) -> Instant {
        let allowance = (self.late_now(request_end) * LATE_FACTOR).min(MAX_LATE_ALLOWANCE);
        // The request itself may wait up to a USB frame before it is on the wire.
        self.reply_due(request_end) + self.adapter.write_hold() + self.reply_margin + allowance
    }

    /// Both ends of the reply window of a request ending at `request_end`.
    pub(crate) fn reply_window(&self, request_end: Instant) -> ReplyWindow {
        ReplyWindow {
            due: self.reply_due(request_end),
            deadline: self.reply_deadline(request_end),
        }
    }

    /// How long an unanswered request holds the line, if it ended `now`.
    pub(crate) fn reply_timeout(&self, now: Instant) -> Duration {
        self.reply_deadline(now) - now
    }

    /// A reply will follow a request ending at `request_end` (written
    /// blind, not waited for): the line is held until its last byte.
    pub(crate) fn reply_on_wire(&mut self, request_end: Instant) {
        self.free_at = self.free_at.max(request_end + self.turnaround + self.frame);
    }

    /// A reply due at `due` arrived at `arrived`.
    pub(crate) fn observe_reply(&mut self, due: Instant, arrived: Instant) {
        let late = arrived.saturating_duration_since(due);
        if late > self.late_now(arrived) {
            self.late = late;
            self.late_at = arrived;
        }
    }

    fn late_now(&self, now: Instant) -> Duration {
        let age = now.saturating_duration_since(self.late_at).as_secs_f64();
        self.late.mul_f64(0.5f64.powf(age / LATE_HALF_LIFE_S))
    }

    /// The last write left `by` later than it was accounted for: the line
    /// frees that much later.
    pub(crate) fn hold_longer(&mut self, by: Duration) {
        self.free_at += by;
    }

    /// A reply arrived (or its time ran out) at `at`: the line is free from then.
    pub(crate) fn line_free(&mut self, at: Instant) {
        self.free_at = self.free_at.max(at);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clock(now: Instant) -> WireClock {
        WireClock::new(500_000, &Timing::default(), now)
    }

    #[test]
    fn frames_queue_behind_each_other() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        let frame = Duration::from_micros(400);
        assert_eq!(c.host_frames(t0, 1), t0 + frame);
        // Handed over while the first is on the wire: starts when it ends.
        assert_eq!(c.host_frames(t0 + frame / 2, 2), t0 + frame * 3);
        // Handed over to an idle line: starts at once.
        let later = t0 + Duration::from_millis(5);
        assert_eq!(c.host_frames(later, 1), later + frame);
    }

    #[test]
    fn next_write_leads_the_free_line() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        let end = c.host_frames(t0, 1);
        assert_eq!(c.write_at(), end - Duration::from_micros(300));
    }

    #[test]
    fn lead_stays_below_a_frame() {
        let t0 = Instant::now();
        let timing = Timing {
            write_lead_us: 5_000,
            ..Timing::default()
        };
        let mut c = WireClock::new(500_000, &timing, t0);
        let end = c.host_frames(t0, 1);
        assert_eq!(c.write_at(), end - Duration::from_micros(300));
        c.set_baud(19_200);
        let end = c.host_frames(end, 1);
        assert_eq!(c.write_at(), end - Duration::from_micros(5_000));
    }

    #[test]
    fn reply_deadline_covers_turnaround_frame_and_margin() {
        let t0 = Instant::now();
        let c = clock(t0);
        assert_eq!(
            c.reply_deadline(t0),
            t0 + Duration::from_micros(100 + 400 + 5000)
        );
    }

    #[test]
    fn late_replies_widen_the_deadline_for_a_while() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        let base = c.reply_deadline(t0) - t0;
        // A reply 26 ms late (a stalled pty worker): twice that, capped.
        let due = c.reply_due(t0);
        c.observe_reply(due, due + Duration::from_millis(26));
        let wide = c.reply_deadline(t0) - t0;
        assert_eq!(wide, base + Duration::from_millis(20));
        // An on-time reply does not shrink it; time does (half-life 60 s).
        let later = t0 + Duration::from_secs(60);
        c.observe_reply(c.reply_due(later), c.reply_due(later));
        assert_eq!(
            c.reply_deadline(later) - later,
            wide,
            "13 ms doubled, capped"
        );
        let much_later = t0 + Duration::from_secs(180);
        let less = c.reply_deadline(much_later) - much_later;
        assert!(less > base && less < wide, "{less:?}");
    }

    #[test]
    fn a_reply_frees_the_line_when_it_arrives() {
        let t0 = Instant::now();
        let mut c = clock(t0);
        c.host_frames(t0, 1);
        let rx = t0 + Duration::from_micros(900);
        c.line_free(rx);
        assert_eq!(c.free_at(), rx);
        c.line_free(t0);
        assert_eq!(c.free_at(), rx, "the line never frees in the past");
    }

    #[test]
    fn baud_change_changes_frame_time() {
        let mut c = clock(Instant::now());
        c.set_baud(230_400);
        assert_eq!(c.frame_time().as_nanos(), 868_056);
    }
}
