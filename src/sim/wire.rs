//! The shared half-duplex line and its referee, as a pure function of
//! timestamps (no threads, no clocks read here).
//!
//! - A host frame occupies `[start, start + 200/baud)`, where `start` is its
//!   arrival, or the end of the previous host frame if that one is still on
//!   the wire (a UART FIFO: *queued ahead*).
//! - A device transmission occupies its own interval, scheduled by the caller
//!   (request end + turnaround for a reply, any instant for an announcement).
//! - Any two transmissions whose intervals overlap collide, whoever sent them:
//!   both are marked and counted. Host frames never collide with each other
//!   because they queue.
//! - Each transmission leaves the line at its end: [`Wire::pop_due`] hands
//!   them back in end order so the device sees a request when its last byte
//!   arrives and the host gets a reply when its last byte would.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::protocol::FrameBytes;

use super::busy::BusyMeter;

/// Bits per byte on the wire: start + 8 data + stop (SPEC §1).
const BITS_PER_BYTE: u64 = 10;
/// Bytes per frame.
const FRAME_BYTES: u64 = 20;
const NANOS_PER_SEC: u64 = 1_000_000_000;

/// Time one frame occupies the line at `baud` (200/baud s).
pub(crate) fn frame_time(baud: u32) -> Duration {
    let bits = BITS_PER_BYTE * FRAME_BYTES;
    Duration::from_nanos(bits * NANOS_PER_SEC / u64::from(baud.max(1)))
}

/// A host frame on the line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct HostTx {
    pub start: Instant,
    pub end: Instant,
    pub bytes: FrameBytes,
    /// The baud the host's port was set to when it sent this frame.
    pub baud: Option<u32>,
    pub collided: bool,
}

/// A device transmission (reply or announcement) on the line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct DeviceTx {
    pub start: Instant,
    pub end: Instant,
    /// Index of the sending device in the bus.
    pub slot: usize,
    pub dev_id: u8,
    pub bytes: FrameBytes,
    /// The baud the device sent at.
    pub baud: u32,
    /// A power-up announcement rather than a reply.
    pub spontaneous: bool,
    pub collided: bool,
}

/// A transmission that has left the line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum WireEvent {
    Host(HostTx),
    Device(DeviceTx),
}

/// Where a host frame landed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Placement {
    pub start: Instant,
    pub end: Instant,
    /// It waited behind the previous host frame.
    pub queued: bool,
    /// Pairs of transmissions found overlapping.
    pub collisions: u64,
}

#[derive(Debug, Default)]
pub(crate) struct Wire {
    /// End of the last host frame placed.
    host_free_at: Option<Instant>,
    /// Host frames not yet off the line, in start (= end) order.
    host: VecDeque<HostTx>,
    /// Device transmissions not yet off the line, in end order.
    device: Vec<DeviceTx>,
    /// The last device transmissions that left the line, as spans: a host
    /// frame dated when it was written, read by a simulator thread that
    /// woke late, may start before a reply that has already left.
    ended: VecDeque<(Instant, Instant)>,
    busy: BusyMeter,
}

/// Device transmissions kept after they left the line, for host frames
/// dated into the past (a few ms of replies at any baud jointd uses).
const ENDED_KEPT: usize = 16;

fn overlaps(a: (Instant, Instant), b: (Instant, Instant)) -> bool {
    a.0 < b.1 && b.0 < a.1
}

impl Wire {
    pub(crate) fn new() -> Self {
        Self::default()
    }

    /// Puts a host frame whose bytes arrived at `arrival` on the line.
    pub(crate) fn place_host(
        &mut self,
        bytes: FrameBytes,
        arrival: Instant,
        baud: Option<u32>,
        duration: Duration,
    ) -> Placement {
        let free = self.host_free_at.unwrap_or(arrival);
        let queued = free > arrival;
        let start = free.max(arrival);
        let end = start + duration;
        let mut tx = HostTx {
            start,
            end,
            bytes,
            baud,
            collided: false,
        };
        let mut collisions = 0;
        for d in self
            .device
            .iter_mut()
            .filter(|d| overlaps((d.start, d.end), (start, end)))
        {
            d.collided = true;
            tx.collided = true;
            collisions += 1;
        }
        // A reply already handed to the host cannot be marked; the host
        // frame is, and the overlap counted.
        let met_after_leaving = self
            .ended
            .iter()
            .filter(|span| overlaps(**span, (start, end)))
            .count() as u64;
        tx.collided |= met_after_leaving > 0;
        collisions += met_after_leaving;
        self.host_free_at = Some(end);
        self.busy.add(start, end);
        self.host.push_back(tx);
        Placement {
            start,
            end,
            queued,
            collisions,
        }
    }

    /// Schedules a device transmission; `lead` is line time it holds before
    /// `start` (the turnaround, counted as busy). Returns collisions found.
    pub(crate) fn schedule_device(&mut self, mut tx: DeviceTx, lead: Duration) -> u64 {
        let span = (tx.start, tx.end);
        let mut collisions = 0;
        for h in self
            .host
            .iter_mut()
            .filter(|h| overlaps((h.start, h.end), span))
        {
            h.collided = true;
            tx.collided = true;
            collisions += 1;
        }
        for d in self
            .device
            .iter_mut()
            .filter(|d| overlaps((d.start, d.end), span))
        {
            d.collided = true;
            tx.collided = true;
            collisions += 1;
        }
        let lead_start = tx.start.checked_sub(lead).unwrap_or(tx.start);
        self.busy.add(lead_start, tx.end);
        let at = self.device.partition_point(|d| d.end <= tx.end);
        self.device.insert(at, tx);
        collisions
    }

    /// When the next transmission leaves the line.
    pub(crate) fn next_event(&self) -> Option<Instant> {
        let h = self.host.front().map(|h| h.end);
        let d = self.device.first().map(|d| d.end);
        match (h, d) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// When the next device transmission reaches the host.
    pub(crate) fn next_device_end(&self) -> Option<Instant> {
        self.device.first().map(|d| d.end)
    }

    /// The earliest transmission that has left the line by `now`.
    pub(crate) fn pop_due(&mut self, now: Instant) -> Option<WireEvent> {
        let h = self.host.front().map(|h| h.end).filter(|e| *e <= now);
        let d = self.device.first().map(|d| d.end).filter(|e| *e <= now);
        match (h, d) {
            (Some(he), Some(de)) if de < he => Some(self.device_left()),
            (Some(_), _) => self.host.pop_front().map(WireEvent::Host),
            (None, Some(_)) => Some(self.device_left()),
            (None, None) => None,
        }
    }

    /// The first device transmission leaves the line (remembered a while).
    fn device_left(&mut self) -> WireEvent {
        let d = self.device.remove(0);
        if self.ended.len() == ENDED_KEPT {
            self.ended.pop_front();
        }
        self.ended.push_back((d.start, d.end));
        WireEvent::Device(d)
    }

    /// Host frames waiting for or on the line (the host's UART FIFO depth).
    pub(crate) fn host_backlog(&self) -> usize {
        self.host.len()
    }

    /// Line busy time up to `at`.
    pub(crate) fn busy_until(&self, at: Instant) -> Duration {
        self.busy.busy_until(at)
    }

    /// Housekeeping: folds old busy intervals.
    pub(crate) fn fold(&mut self, now: Instant) {
        self.busy.fold(now);
    }

    /// Drops everything in flight (the line was unplugged).
    pub(crate) fn clear_in_flight(&mut self) {
        self.host.clear();
        self.device.clear();
        self.ended.clear();
        self.host_free_at = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BAUD: u32 = 500_000;

    fn reply(start: Instant, slot: usize) -> DeviceTx {
        DeviceTx {
            start,
            end: start + frame_time(BAUD),
            slot,
            dev_id: 1,
            bytes: [0; 20],
            baud: BAUD,
            spontaneous: false,
            collided: false,
        }
    }

    #[test]
    fn frame_time_is_200_bit_times() {
        assert_eq!(frame_time(500_000), Duration::from_micros(400));
        assert_eq!(frame_time(19_200).as_nanos(), 10_416_666);
    }

    #[test]
    fn back_to_back_host_frames_queue_without_colliding() {
        let t0 = Instant::now();
        let f = frame_time(BAUD);
        let mut w = Wire::new();
        let a = w.place_host([1; 20], t0, Some(BAUD), f);
        let b = w.place_host([2; 20], t0, Some(BAUD), f);
        assert!(!a.queued && b.queued);
        assert_eq!(b.start, a.end);
        assert_eq!(a.collisions + b.collisions, 0);
        assert_eq!(w.next_event(), Some(a.end));
        assert!(w.pop_due(a.end - Duration::from_nanos(1)).is_none());
        assert!(matches!(w.pop_due(b.end), Some(WireEvent::Host(h)) if h.bytes == [1; 20]));
        assert_eq!(w.busy_until(b.end), 2 * f);
    }

    #[test]
    fn host_frame_during_a_reply_collides_both() {
        let t0 = Instant::now();
        let f = frame_time(BAUD);
        let mut w = Wire::new();
        assert_eq!(
            w.schedule_device(reply(t0, 0), Duration::from_micros(100)),
            0
        );
        let p = w.place_host([1; 20], t0 + f / 2, Some(BAUD), f);
        assert_eq!(p.collisions, 1);
        let Some(WireEvent::Device(d)) = w.pop_due(t0 + 2 * f) else {
            panic!("reply first")
        };
        assert!(d.collided);
        let Some(WireEvent::Host(h)) = w.pop_due(t0 + 2 * f) else {
            panic!("host next")
        };
        assert!(h.collided);
    }

    #[test]
    fn a_host_frame_dated_into_a_reply_that_already_left_collides() {
        let t0 = Instant::now();
        let f = frame_time(BAUD);
        let mut w = Wire::new();
        w.schedule_device(reply(t0, 0), Duration::ZERO);
        assert!(matches!(w.pop_due(t0 + f), Some(WireEvent::Device(_))));
        // Read after the reply left, written while it was on the line.
        let p = w.place_host([1; 20], t0 + f / 2, Some(BAUD), f);
        assert_eq!(p.collisions, 1);
        let Some(WireEvent::Host(h)) = w.pop_due(t0 + 2 * f) else {
            panic!("the host frame")
        };
        assert!(h.collided);
        // Written after it ended: no collision.
        let q = w.place_host([2; 20], t0 + 2 * f, Some(BAUD), f);
        assert_eq!(q.collisions, 0);
    }

    #[test]
    fn simultaneous_replies_collide_and_touching_ones_do_not() {
        let t0 = Instant::now();
        let f = frame_time(BAUD);
        let mut w = Wire::new();
        w.schedule_device(reply(t0, 0), Duration::ZERO);
        assert_eq!(w.schedule_device(reply(t0, 1), Duration::ZERO), 1);
        assert_eq!(w.schedule_device(reply(t0 + f, 2), Duration::ZERO), 0);
        let h = w.place_host([0; 20], t0 + 2 * f, Some(BAUD), f);
        assert_eq!(h.collisions, 0);
    }
}
