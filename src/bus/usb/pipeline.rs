//! Wire-timed pipelining through a latent USB adapter.
//!
//! Behind a USB adapter a reply reaches the host a USB frame (CH340,
//! CP2102), or a latency timer (FTDI), after it left the wire, while the
//! wire itself is free a turnaround after the reply's last byte. Waiting for
//! each reply before the next write leaves the wire idle for that whole
//! round trip. Instead the owner writes each transfer (control broadcasts
//! and a poll) when the *wire* will be free, blind to replies still held
//! in the adapter, and matches them when they come ([`Inflight`]).
//!
//! What makes that safe is bounding when a write reaches the wire: host
//! bytes leave at the next USB (micro)frame boundary, so at the latest a
//! period (and the write's reach) after the write. Until the frame clock
//! is known, and whenever the host reads replies too late for it to show,
//! the wire is held that long after each write: up to a period lost per
//! transfer, never the adapter's hold of a reply. The boundaries are
//! not visible to the host, but the adapter also hands received bytes to
//! the host at boundaries, so every read the bytes wake is a boundary plus
//! the host's own wake-up delay (never minus). [`FramePhase`] keeps the
//! last arrivals and takes as the boundary the start of the cluster they
//! form (so a stalled thread's late read does not move it). That start is
//! itself late by the host's least wake-up delay: a write is taken to make
//! a boundary only with its reach and the host's measured wake-up
//! lateness to spare.
//!
//! Each write is aimed early in the frame before the boundary it should
//! leave at (0.8 of a period before it), so a write, or the adapter's
//! taking of it, may be late by most of a frame and still make it. A write that comes later than planned (the host stalled) is
//! modelled as leaving at the later boundary it may have missed into: the
//! next transfer is placed after the latest the wire can be busy, so the
//! one thing the host cannot observe never makes a collision.
//!
//! Where the port says when the adapter took a write (a USB-serial
//! driver's output count), the host does observe it: each write is then
//! held as on time and seen taken before the next ([`super::confirm`]),
//! and the guard's reach and sentinels are not needed.
//!
//! Pure: every instant is passed in.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::confirm::Confirm;
use super::frame_clock::FramePhase;
use super::guard::{
    Change, PipelineMode, UsbGuard, SENTINEL_EVERY, SENTINEL_LEAD, SENTINEL_MIN_MARGIN,
};
use crate::bus::packets::PacketMark;
use crate::bus::wire::{ReplyWindow, Want};
use crate::protocol::FRAME_LEN;
use crate::transport::adapter::AdapterModel;

/// A write is still aimed at a boundary this close: whether it makes it
/// or the next is then not known, and the wire is held for the later one
/// ([`UsbPipeline::released`]). Below the reach so that a host that
/// wakes a little late still writes instead of chasing the next frame (on
/// a 125 µs microframe the two are hardly apart).
const WRITE_LAST_CHANCE: Duration = Duration::from_micros(10);
/// Spacing between the wire's modelled end of one transfer and the next
/// release, for the device's turnaround jitter.
const GUARD: Duration = Duration::from_micros(50);
/// Without a frame clock, a write not yet taken is looked at again this
/// many times a frame: each look later than the take holds the wire up to
/// that much longer than it was busy.
const UNCLOCKED_LOOKS_PER_FRAME: u32 = 4;
/// Confirmed writes are made early in the frame before their boundary
/// only once this many in a row were seen untaken just before it.
const CLOCK_CHECKS_TRUSTED: u32 = 8;

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
    /// A sentinel ([`super::guard`]) handed over early enough for its
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

/// Where a transfer of host frames went on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Released {
    /// The boundary it left at, as late as the host's timing allows.
    pub at: Instant,
    /// True when the write came too close to a boundary to know which one
    /// it made (the wire is then held for the later).
    pub ambiguous: bool,
}

/// The pipeline of one latent bus: the frame clock, the replies in flight,
/// and how far it trusts its writes ([`UsbGuard`]).
#[derive(Debug, Clone)]
pub(crate) struct UsbPipeline {
    phase: FramePhase,
    inflight: VecDeque<Inflight>,
    guard: UsbGuard,
    /// True where a sentinel's reply can show its write late: a frame of
    /// 0.5 ms or more, and the reply's arrival known to the frame (no
    /// latency timer longer than it) or [`Self::packets`].
    sentinels: bool,
    /// Behind a latency timer longer than a frame, replies are dated by
    /// the full packets their bytes end ([`crate::bus::packets`]), not by their
    /// arrival.
    packets: bool,
    /// Poll transfers since the last sentinel.
    since_sentinel: u32,
    /// When the sentinel due is to be handed over, once decided (it is
    /// waited for once: a host that wakes too late writes it then).
    sentinel_at: Option<Instant>,
    /// The write being made is a sentinel: the wire is held a frame longer.
    armed: bool,
    /// The port says when the adapter took a write
    /// ([`crate::transport::Transport::unsent`]).
    port_confirms: bool,
    /// The write waiting to be seen taken ([`super::confirm`]).
    confirm: Confirm,
    /// Writes in a row seen untaken just before the boundary the frame
    /// clock aimed them at (none seen taken before it).
    clock_checks: u32,
    /// How late the host sees bytes the adapter hands over (a high
    /// quantile of how late it wakes): the frame clock, learnt from those
    /// sightings, runs up to that much behind the adapter's, so a write is
    /// taken to make a boundary only with that much more to spare (at
    /// most a period), and a sentinel is aimed twice that earlier (the
    /// host also hands it over about that late) and judged on its margin
    /// less it. Being a high quantile, it makes sentinels speak only of
    /// paths later by up to that much more; with at most 200 µs taken, a
    /// sentinel still sees a path late by 0.5 ms, before a write aimed
    /// 0.8 of a frame ahead can collide.
    arrival_lag: Duration,
}

impl UsbPipeline {
    /// The pipeline behind `adapter`; `None` for one without USB frames
    /// (a native line).
    pub(crate) fn for_adapter(
        adapter: AdapterModel,
        recover: Duration,
        now: Instant,
    ) -> Option<Self> {
        let period = adapter.usb_frame()?;
        let mut pipeline = Self {
            packets: false,
            phase: FramePhase::new(period),
            inflight: VecDeque::new(),
            guard: UsbGuard::new(recover, adapter.replies_next_frame(), now),
            sentinels: false,
            since_sentinel: 0,
            sentinel_at: None,
            armed: false,
            port_confirms: false,
            confirm: Confirm::default(),
            clock_checks: 0,
            arrival_lag: Duration::ZERO,
        };
        pipeline.set_adapter(adapter);
        Some(pipeline)
    }

    /// How `adapter` (with this pipeline's USB frame) lets replies date
    /// their writes. A sentinel's reply shows its write a frame late only
    /// where a frame is 0.5 ms or more (a host reads replies 30-90 µs late)
    /// and the reply reaches the host at the frame after the adapter lets
    /// it go (a latency timer no longer than one), or, behind a longer
    /// timer, where its bytes end a full packet. Where a reply reaches the
    /// host at the next frame, lockstep costs what guarded does
    /// ([`UsbGuard::new`]).
    pub(crate) fn set_adapter(&mut self, adapter: AdapterModel) {
        self.sentinels = self.period() >= Duration::from_micros(500);
        self.packets = adapter.packet_payload().is_some();
        self.guard
            .set_replies_next_frame(adapter.replies_next_frame());
    }

    /// True when the next poll transfer should be a sentinel (not while
    /// writes are confirmed: a late one costs nothing there).
    pub(crate) fn sentinel_due(&self) -> bool {
        self.sentinels
            && !self.confirming()
            && self.active()
            && self.guard.blind()
            && self.since_sentinel + 1 >= SENTINEL_EVERY
    }

    /// While a sentinel is due: until when to wait before handing it over,
    /// [`SENTINEL_LEAD`] of a frame (and twice the arrival lag) before the
    /// boundary [`Self::write_at`] aims at when first asked. `None` once that time has come (or passed:
    /// a host that woke late writes it at once rather than chase the next
    /// frame, which would hold every other write back with it).
    pub(crate) fn sentinel_wait(&mut self, free_at: Instant, now: Instant) -> Option<Instant> {
        if !self.sentinel_due() {
            return None;
        }
        let at = match self.sentinel_at {
            Some(at) => at,
            None => {
                let release = self.aimed_boundary(free_at, now);
                // The boundary may lie the arrival lag before the clock's,
                // and this host hands the write over about as late again
                // as it asks to wake.
                let at = release
                    .checked_sub(self.period().mul_f64(SENTINEL_LEAD) + self.arrival_lag * 2)
                    .unwrap_or(release);
                *self.sentinel_at.insert(at)
            }
        };
        (now < at).then_some(at)
    }

    /// The next write is the sentinel: its release holds the wire a frame
    /// longer, and [`Self::track`] marks its reply.
    pub(crate) fn arm_sentinel(&mut self) {
        self.armed = true;
        self.sentinel_at = None;
    }

    pub(crate) fn guard(&self) -> &UsbGuard {
        &self.guard
    }

    pub(crate) fn guard_mut(&mut self) -> &mut UsbGuard {
        &mut self.guard
    }

    /// How late a write may reach the adapter and still leave where the
    /// wire is held for it. Pipelined, at most a period: on a 125 µs
    /// microframe a write is then held for the next one.
    fn reach(&self) -> Duration {
        if self.armed {
            // At least a frame: a write handed a tenth of a frame before
            // its boundary and late by up to a frame leaves one frame
            // later. Guarded, no less than any other write is held for.
            return self.period().max(self.guard.reach());
        }
        match self.guard.mode() {
            PipelineMode::Pipelined => self.guard.reach().min(self.period()),
            _ => self.guard.reach(),
        }
    }

    pub(crate) fn period(&self) -> Duration {
        self.phase.period()
    }

    /// True once writes can be timed by the frame clock (before that they
    /// are written blind all the same, each taken to leave as late as it
    /// may).
    pub(crate) fn active(&self) -> bool {
        self.phase.known()
    }

    /// The host woke on bytes from the adapter at `at`.
    pub(crate) fn arrival(&mut self, at: Instant) {
        self.phase.arrival(at);
    }

    /// The host sees bytes the adapter hands over up to `lag` late.
    pub(crate) fn set_arrival_lag(&mut self, lag: Duration) {
        self.arrival_lag = lag;
    }

    pub(crate) fn arrival_lag(&self) -> Duration {
        self.arrival_lag
    }

    /// When to write the next transfer so that it leaves at the first
    /// boundary the wire allows (`free_at` plus the guard): the middle of
    /// the frame before it. A boundary the host can no longer make is
    /// skipped for the next.
    /// Before the frame clock is known: once the wire is free and the
    /// guard has passed (a write leaves at the earliest right after it is
    /// made; [`Self::latest_release`] holds the wire for the latest).
    /// While a write waits to be seen taken, nothing else is written: the
    /// next look at the port's count is the time to wake.
    pub(crate) fn write_at(&self, free_at: Instant, now: Instant) -> Instant {
        if let Some(check) = self.confirm.check_at(self.period()) {
            return check;
        }
        if !self.active() {
            return free_at + GUARD;
        }
        let release = self.aimed_boundary(free_at, now);
        let at = release.checked_sub(self.lead()).unwrap_or(release);
        if self.confirming() && self.clock_checks < CLOCK_CHECKS_TRUSTED {
            // Not before the wire is free while the count has not shown
            // the frame clock right: its estimate can be off by most of a
            // frame on a host that reads replies late, and a write made
            // early in the frame before the boundary it aims at is then
            // taken at the boundary before, into the reply still on the
            // wire. Made once the wire is free, no boundary can take it
            // too early, and the count says when one took it late.
            return at.max(free_at + GUARD);
        }
        at
    }

    /// How long before the boundary it aims at a write is made: in the
    /// frame before, early in it.
    fn lead(&self) -> Duration {
        self.period()
            .mul_f64(self.guard.lead())
            .max(self.period() / 2)
    }

    /// The first boundary the wire allows that the host can still make.
    fn aimed_boundary(&self, free_at: Instant, now: Instant) -> Instant {
        let by_wire = self.phase.boundary_at_or_after(free_at + GUARD);
        let by_host = self.phase.boundary_after(now + WRITE_LAST_CHANCE);
        by_wire.max(by_host)
    }

    /// A write was handed to the port at `handed`: the latest boundary it
    /// leaves at if it reaches the adapter within the reach (the later one
    /// if it came close enough to miss the first). Beyond `pipelined` every
    /// write is held for a later one by design, not as a late host's.
    pub(crate) fn released(&self, handed: Instant) -> Released {
        let first = self.phase.boundary_after(handed);
        if self.confirming() {
            // Held as on time; the port's count says otherwise in time.
            return Released {
                at: first,
                ambiguous: false,
            };
        }
        // The clock is off by less than a period however late the host.
        let lag = self.arrival_lag.min(self.period());
        let latest = self.phase.boundary_after(handed + self.reach() + lag);
        Released {
            at: latest,
            ambiguous: latest != first
                && self.guard.mode() == PipelineMode::Pipelined
                && !self.armed,
        }
    }

    /// The latest a write handed over at `handed` leaves, whether the frame
    /// clock is known or not (then: a whole period and the write's reach).
    pub(crate) fn latest_release(&self, handed: Instant) -> Released {
        if self.active() {
            return self.released(handed);
        }
        Released {
            at: handed + self.period() + self.reach(),
            ambiguous: false,
        }
    }

    /// Where the wire is held for a write that asks no reply (control
    /// frames only), handed over at `handed`. Backed off: the whole
    /// frames of the reach earlier than its latest boundary, never before
    /// the boundary it leaves at on time (for a write aimed 0.9 frame
    /// before its boundary on a 1 ms frame, that one). Later, what follows
    /// queues behind it in the adapter's transmit FIFO; no reply is on its
    /// way for that to collide with. A write with a reply is held at least
    /// those whole frames past its own boundary, which a FIFO pushes
    /// nothing past: a queue whose arrivals are each at most that late
    /// finishes each at most that late. (Held only for its on-time
    /// boundary, a write handed over late in its frame, such as one that
    /// goes at a sentinel's hand-over time, would leave two frames late
    /// within the reach.) Otherwise as [`Self::latest_release`].
    pub(crate) fn release_without_reply(&self, handed: Instant) -> Released {
        if self.active() && self.guard.mode() != PipelineMode::Pipelined {
            let on_time = self.phase.boundary_after(handed);
            let latest = self.released(handed).at;
            let period = self.period();
            let frames = self.reach().as_nanos() / period.as_nanos().max(1);
            let covered = period.saturating_mul(u32::try_from(frames).unwrap_or(u32::MAX));
            return Released {
                at: latest
                    .checked_sub(covered)
                    .map_or(on_time, |t| t.max(on_time)),
                ambiguous: false,
            };
        }
        self.latest_release(handed)
    }

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

    /// When the reply to a write handed over at `handed` reaches the host
    /// if the write made the first boundary after it; `reply_end` is when
    /// the reply leaves the adapter's hold, the write leaving as late as
    /// the reach allows. `None` while the frame clock is unknown.
    /// How much later than the first boundary after it a write handed
    /// over at `handed` is held for.
    fn held(&self, handed: Instant) -> Duration {
        self.released(handed)
            .at
            .saturating_duration_since(self.phase.boundary_after(handed))
    }

    fn on_time_read(&self, handed: Instant, reply_end: Instant) -> Option<Instant> {
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
    fn answered(&mut self, inflight: &Inflight, at: Instant) -> Option<Change> {
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
    fn answered_packet(&mut self, inflight: &Inflight, mark: PacketMark) -> Option<Change> {
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

    /// The port was lost or reopened: nothing is in flight, and the frame
    /// clock is learnt again.
    pub(crate) fn reset(&mut self) {
        self.inflight.clear();
        self.phase.forget();
        self.clock_checks = 0;
        self.armed = false;
        self.sentinel_at = None;
        self.confirm.reset();
    }
}

#[path = "pipeline_confirmed.rs"]
mod confirmed;

#[cfg(test)]
#[path = "pipeline_tests.rs"]
mod tests;
