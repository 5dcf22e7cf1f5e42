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
use super::guard::{PipelineMode, UsbGuard, SENTINEL_EVERY, SENTINEL_LEAD};
use crate::transport::adapter::AdapterModel;
pub(crate) use inflight::Inflight;

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
#[path = "pipeline_inflight.rs"]
mod inflight;
#[path = "pipeline_verdicts.rs"]
mod verdicts;

#[cfg(test)]
#[path = "pipeline_tests.rs"]
mod tests;
