//! What a reply's arrival says of its write: on time, or a USB frame
//! late (the write reached the adapter after the boundary it was aimed
//! at). Late writes keep a backed-off pipeline from stepping down; late
//! sentinels back it off ([`super::super::guard`]).

use std::time::{Duration, Instant};

use super::super::guard::Change;
use super::{Inflight, UsbPipeline, GUARD};
use crate::bus::packets::PacketMark;
use crate::protocol::FRAME_LEN;

impl UsbPipeline {
    /// How much later than the first boundary after it a write handed
    /// over at `handed` is held for.
    pub(super) fn held(&self, handed: Instant) -> Duration {
        self.released(handed)
            .at
            .saturating_duration_since(self.phase.boundary_after(handed))
    }

    /// When the reply to a write handed over at `handed` reaches the host
    /// if the write made the first boundary after it; `reply_end` is when
    /// the reply leaves the adapter's hold, the write leaving as late as
    /// the reach allows. `None` while the frame clock is unknown.
    pub(super) fn on_time_read(&self, handed: Instant, reply_end: Instant) -> Option<Instant> {
        self.active().then(|| {
            let held = self.held(handed);
            // The latest the reply may end (the device's turnaround
            // varies): a reply ending just before a boundary is not taken
            // for late when it ends just after.
            let end = reply_end.checked_sub(held).unwrap_or(reply_end) + GUARD;
            self.phase.boundary_after(end)
        })
    }

    /// True when a reply read at `at`, due at `on_time`, says its write
    /// slipped a frame, or two where the widened guard holds the wire for
    /// that (see [`Self::answered`]).
    fn slipped(&self, on_time: Instant, at: Instant) -> bool {
        let after = at.saturating_duration_since(on_time);
        let period = self.period();
        (1..=self.guard.frames_of_slack()).any(|frames| {
            let frames = f64::from(frames);
            after >= period.mul_f64(frames - 0.1) && after <= period.mul_f64(frames + 0.25)
        })
    }

    /// A reply waited for (lockstep, or a one-shot request) to a write
    /// handed over at `handed` (the reply leaving the adapter's hold at
    /// `reply_end`, see [`Self::track`]) was read at `at`. A write seen a
    /// frame late keeps a backed-off mode from stepping down, as a blind
    /// poll's does.
    pub(crate) fn waited_reply(&mut self, handed: Instant, reply_end: Instant, at: Instant) {
        if let Some(on_time) = self.on_time_read(handed, reply_end) {
            if self.slipped(on_time, at) {
                self.guard.write_seen_late(at);
            }
        }
    }

    /// The reply of `inflight` was read at `at`, `packet` the full packet a
    /// byte of it ended, if one did: dated by that packet where its poll
    /// was tracked for packets, else by its arrival.
    pub(crate) fn replied(
        &mut self,
        inflight: &Inflight,
        at: Instant,
        packet: Option<PacketMark>,
    ) -> Option<Change> {
        match packet {
            Some(mark) if inflight.packet_ref.is_some() => self.answered_packet(inflight, mark),
            _ => self.answered(inflight, at),
        }
    }

    /// The reply of `inflight` reached the host at `at`: a frame or more
    /// after it would have if its write had made its boundary, the write
    /// reached the adapter late. A backed-off pipeline does not step down
    /// while it sees that; sentinels late often enough back it off.
    pub(super) fn answered(&mut self, inflight: &Inflight, at: Instant) -> Option<Change> {
        let on_time = inflight.on_time?;
        // Later than the frames the wire is held for is not a write that
        // slipped (that collides, or shows as garbage): it is the reply of
        // a newer poll of the same block matched to an older one whose
        // reply was lost.
        // Under three quarters of a frame is the host reading late.
        // A write that slipped a frame makes its reply reach the host at the
        // next boundary, read promptly: a frame after on time, give or take
        // the estimate's error and the host's usual wake-up. A read later
        // than that is the host's, not the path's, and says nothing.
        self.verdict(inflight.sentinel, on_time, at)
    }

    /// Behind a latency timer: byte `mark.byte` of `inflight`'s reply ended
    /// a full packet, which the host read at `mark.read_at`. The packet
    /// leaves the adapter at the frame after that byte came in: read a
    /// frame later than on time, the poll's write slipped a frame.
    pub(super) fn answered_packet(
        &mut self,
        inflight: &Inflight,
        mark: PacketMark,
    ) -> Option<Change> {
        let r = inflight.packet_ref?;
        let after_it = FRAME_LEN.saturating_sub(usize::from(mark.byte)) as u32;
        let byte_in = r.reply_end.checked_sub(r.byte * after_it)?;
        // As for a reply's end: the device's turnaround varies.
        let on_time = self.phase.boundary_after(byte_in + GUARD);
        self.verdict(inflight.sentinel, on_time, mark.read_at)
    }

    /// What a read at `at` of what was due at `on_time` says: a sentinel
    /// late or on time (or nothing, read too late to tell), another write
    /// seen a frame late.
    fn verdict(&mut self, sentinel: bool, on_time: Instant, at: Instant) -> Option<Change> {
        let after = at.saturating_duration_since(on_time);
        let period = self.period();
        let slipped = self.slipped(on_time, at);
        if sentinel {
            let on_time_read = after < period.mul_f64(0.75);
            return match (slipped, on_time_read) {
                (true, _) => self.guard.sentinel(true, at),
                (false, true) => self.guard.sentinel(false, at),
                (false, false) => None,
            };
        }
        if slipped {
            self.guard.write_seen_late(at);
        }
        None
    }
}
