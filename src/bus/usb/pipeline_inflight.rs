//! The pipeline's polls in flight: each poll written blind is tracked
//! with what its reply should look like on time, and a reply read later is
//! matched to the poll it answers, or to none.

use std::time::{Duration, Instant};

use super::super::guard::SENTINEL_MIN_MARGIN;
use super::UsbPipeline;
use crate::bus::wire::{ReplyWindow, Want};
use crate::protocol::FRAME_LEN;

/// A poll written blind: its reply is matched when the adapter hands it over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Inflight {
    pub want: Want,
    pub window: ReplyWindow,
    /// When its write was handed to the port (for the round-trip histogram).
    pub handed: Instant,
    /// Bytes read when its write began: a reply whose first byte was among
    /// them was on its way before the poll and answers none.
    pub read_before: u64,
    /// When its reply reaches the host if the write made the first
    /// boundary after it (the frame clock known): a reply a frame later
    /// shows a write that reached the adapter late.
    pub on_time: Option<Instant>,
    /// A sentinel ([`super::super::guard`]) handed over early enough for its
    /// lateness to say something of the path.
    pub sentinel: bool,
    /// Behind a latency timer longer than a frame: when its reply's last
    /// byte leaves the wire if the write made the first boundary after it,
    /// and a byte's time, to date a full packet that a byte of it ends.
    pub packet_ref: Option<PacketRef>,
}

/// When a reply's bytes leave the wire on time (see [`Inflight`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PacketRef {
    pub reply_end: Instant,
    pub byte: Duration,
}

impl UsbPipeline {
    /// A poll written blind, its reply expected in `window`.
    /// (Tracked only while writes are blind.)
    /// `reply_end`: when the reply leaves the adapter's hold (the latency
    /// timer's end, if it has one), the write leaving as late as the reach
    /// allows. Ends an armed sentinel.
    /// `wire_end`: when the reply's last byte leaves the wire, the write
    /// leaving as late as the reach allows; `frame`: a frame's wire time.
    pub(crate) fn track(
        &mut self,
        want: Want,
        window: ReplyWindow,
        (handed, read_before): (Instant, u64),
        reply_end: Instant,
        (wire_end, frame): (Instant, Duration),
    ) {
        let (on_time, packet_ref) = if self.packets {
            let held = self.held(handed);
            let packet_ref = self.active().then(|| PacketRef {
                reply_end: wire_end.checked_sub(held).unwrap_or(wire_end),
                byte: frame / FRAME_LEN as u32,
            });
            (None, packet_ref)
        } else {
            (self.on_time_read(handed, reply_end), None)
        };
        self.confirm.carried_poll();
        let armed = std::mem::take(&mut self.armed);
        // An attempt counts as one whether or not it can be judged: each
        // holds the wire a frame.
        self.since_sentinel = if armed {
            0
        } else {
            self.since_sentinel.saturating_add(1)
        };
        let margin = self
            .phase
            .boundary_after(handed)
            .saturating_duration_since(handed)
            .saturating_sub(self.arrival_lag);
        // Handed over too close to its boundary (the host woke late), its
        // lateness would be the host's as much as the path's: not judged.
        let judged = on_time.is_some() || packet_ref.is_some();
        let sentinel = armed && judged && margin >= SENTINEL_MIN_MARGIN;
        self.inflight.push_back(Inflight {
            want,
            window,
            handed,
            read_before,
            on_time,
            sentinel,
            packet_ref,
        });
    }

    /// The oldest poll in flight that a reply to `want` answers, taken
    /// out; `followed_by` replies to `want` were read after it in the same
    /// batch, and its first byte was byte `first_byte` of the stream. A
    /// device answers a read once and in order, so of the replies to one
    /// block in hand only the last ones answer the polls in flight: one
    /// before them was on the wire before those polls were written (a
    /// power-up announcement, a reply given up on), and the adapter held it
    /// until it passed them on together. A reply begun before the oldest
    /// poll's write was even started answers none of them, whichever batch
    /// its end came in.
    pub(crate) fn take(
        &mut self,
        want: Want,
        followed_by: usize,
        first_byte: u64,
    ) -> Option<Inflight> {
        let waiting = self.inflight.iter().filter(|i| i.want == want).count();
        if followed_by >= waiting {
            return None;
        }
        let pos = self.inflight.iter().position(|i| i.want == want)?;
        if self.inflight[pos].read_before > first_byte {
            return None;
        }
        self.inflight.remove(pos)
    }

    /// Polls whose deadline passed by `now`, taken out, oldest first.
    pub(crate) fn expired(&mut self, now: Instant) -> Vec<Inflight> {
        let mut gone = Vec::new();
        self.inflight.retain(|i| {
            let late = i.window.deadline <= now;
            if late {
                gone.push(*i);
            }
            !late
        });
        gone
    }

    /// The earliest deadline in flight.
    pub(crate) fn next_deadline(&self) -> Option<Instant> {
        self.inflight.iter().map(|i| i.window.deadline).min()
    }

    pub(crate) fn in_flight(&self) -> usize {
        self.inflight.len()
    }
}
