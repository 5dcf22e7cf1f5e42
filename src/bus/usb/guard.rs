//! The USB pipeline's self-protection: how much it trusts its writes to
//! reach the adapter in time, learnt from what collisions leave behind.
//!
//! Where the port cannot say when the adapter took a write (a pty, a
//! driver without an output count, `timing.usb_confirm = false`; otherwise
//! writes are confirmed, [`super::confirm`], and only a count given up
//! on comes here), the pipeline ([`super::pipeline`]) writes each
//! transfer blind, aimed at a USB frame boundary, and holds the wire for the latest boundary the
//! write may leave at if it reaches the adapter within the *reach*. On a
//! path whose writes come later than that now and then (a busy host, a hub
//! shared with a camera, a VM), a write misses its boundary, leaves a frame
//! later, and collides with the next transfer. Nothing the host sees tells
//! it in advance; the aftermath does:
//! - garbled bytes (CRC errors, bytes skipped to find a frame): the host's
//!   side of a reply that collided;
//! - a reply lost, or matched after its deadline, from a device that still
//!   answers (a device that is simply gone never answers again, and is not
//!   evidence).
//!
//! Collisions come from the tail of the path's delay, rare by nature: on
//! a path late one write in a thousand, the first may come seconds in.
//! The body of the delay shows sooner and at no risk: one poll transfer
//! in [`SENTINEL_EVERY`] is a *sentinel*, written only a tenth of a frame
//! before its boundary with the wire held a frame longer for it. A
//! sentinel late by more than its margin leaves a frame later, harmlessly,
//! and its reply shows it. [`SENTINEL_SLIPS`] of the last
//! [`SENTINEL_WINDOW`] sentinels late is evidence like a collision's: on
//! the late path of the goals (p50 38 µs, p99 150 µs) about one sentinel
//! in five is late, on a clean path none. The rule is a heuristic on the
//! body of the delay, and errs on the safe side: a path whose writes are
//! all between 0.1 and 0.7 ms late never collides pipelined, yet backs
//! off.
//!
//! # The ladder
//! | mode | write aimed | reach held for | per-transfer cost on a 1 ms frame |
//! |---|---|---|---|
//! | `pipelined` | 0.8 frame before its boundary | 200 µs | none (the bound) |
//! | `guarded` | 0.9 frame before | 1.5 ms | one frame after each poll's reply: a write late by up to 1.5 ms leaves at most one frame late into a wire held for it; a control-only transfer (no reply to collide with) goes before each poll and is held for its on-time frame when handed over where it is aimed |
//! | `guarded`, widened | 0.9 frame before | 2.5 ms | two frames after each poll's reply, for a path whose tail passes guarded's reach (a pty behind a loaded host): 0.8 / 0.4 of the bound with one control-only transfer per poll |
//! | `lockstep` | a poll's transfer after the previous reply, a control-only one before it | any delay | a USB round trip per poll: on an adapter without a latency timer the same 3 frames as `guarded` |
//!
//! A write whose delay can reach a whole USB frame cannot be told from one
//! that made its boundary until its reply is due, a frame after the next
//! transfer must be written: no placement inside the frame helps, the
//! wire must be held one frame longer after every reply (`guarded`).
//! Writes that ask no reply need no such hold: the adapter's transmit
//! FIFO queues a late one ahead of what follows, and a FIFO whose
//! arrivals are each at most a frame late finishes each at most a frame
//! late, which the next poll's hold covers. Below that a write aimed
//! earlier in the frame is free.
//!
//! # Backing off and back
//! On an adapter that hands a reply over at the next USB frame (no
//! latency timer: CH340, CP2102), `lockstep` costs what `guarded` does
//! and no delay can make it collide, so its ladder has no `guarded` step.
//! Behind a latency timer `lockstep` waits the timer out for every poll
//! (on a 16 ms timer 0.3 / 0.2 of the bound), so an incident in `guarded`
//! first widens its reach by a frame, and only one in the widened guard
//! goes to `lockstep`; stepping down, `lockstep` returns to the widened
//! guard, which narrows before going back to `pipelined`.
//! One incident steps up one mode at the next write (the evidence shows
//! within a reply deadline, a few ms). Evidence from transfers written
//! under the previous mode ([`SETTLE`]) does not step again. A mode held
//! clean for the recovery time steps down one; a step down followed by an
//! incident within twice the recovery time doubles the next recovery time
//! (up to [`MAX_RECOVER_FACTOR`] times): a path that is late for good does not
//! make the pipeline oscillate. The factor halves again after a clean
//! recovery time at the bottom.
//!
//! Pure: every instant is passed in.

use std::collections::VecDeque;
use std::fmt;
use std::time::{Duration, Instant};

use serde::Serialize;

/// The pipeline's modes, least cautious first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum PipelineMode {
    /// Writes aimed 0.8 frame before their boundary, trusted to reach the
    /// adapter within 200 µs: the adapter's bound.
    Pipelined,
    /// Writes aimed 0.9 frame before, the wire held for a poll's write
    /// late by up to 1.5 ms; a control-only transfer before each poll.
    Guarded,
    /// A transfer with a poll waits for the previous poll's reply, a
    /// control-only transfer goes before each: no poll is written blind,
    /// any delay is safe.
    Lockstep,
}

impl PipelineMode {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pipelined => "pipelined",
            Self::Guarded => "guarded",
            Self::Lockstep => "lockstep",
        }
    }

    /// The next mode up a ladder that has the `guarded` step or not.
    fn up(self, guarded: bool) -> Option<Self> {
        match self {
            Self::Pipelined if guarded => Some(Self::Guarded),
            Self::Pipelined | Self::Guarded => Some(Self::Lockstep),
            Self::Lockstep => None,
        }
    }

    /// The next mode down such a ladder.
    fn down(self, guarded: bool) -> Option<Self> {
        match self {
            Self::Pipelined => None,
            Self::Lockstep if guarded => Some(Self::Guarded),
            Self::Guarded | Self::Lockstep => Some(Self::Pipelined),
        }
    }

    /// Every mode by name, for metrics.
    pub fn all() -> [Self; 3] {
        [Self::Pipelined, Self::Guarded, Self::Lockstep]
    }
}

impl fmt::Display for PipelineMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How long a write made in `pipelined` mode is trusted to take to reach
/// the adapter (the system call, the USB stack, a thread a little late).
const PIPELINED_REACH: Duration = Duration::from_micros(200);
/// In `guarded`: a write reaching the adapter up to 1.5 ms after it was
/// handed over. One handed over where it is aimed (0.9 frame before its
/// boundary) then leaves at most one frame late on a 1 ms frame; the wire
/// is held for the latest boundary each write can leave at within it,
/// wherever it was handed over.
const GUARDED_REACH: Duration = Duration::from_micros(1_500);
/// In `guarded` after an incident there: a frame more, so a write handed
/// over where it is aimed leaves at most two frames late.
const WIDE_GUARDED_REACH: Duration = Duration::from_micros(2_500);
/// In `lockstep` the next write waits for the reply, so the reach only
/// times the wire model of the one transfer out.
const LOCKSTEP_REACH: Duration = Duration::from_micros(1_500);
/// How far before its boundary a write is aimed, as a share of the frame.
const PIPELINED_LEAD: f64 = 0.8;
const GUARDED_LEAD: f64 = 0.9;
/// Evidence this soon after a change comes from transfers written before
/// it: the reply deadline behind a latent adapter, with room.
pub(crate) const SETTLE: Duration = Duration::from_millis(50);
/// The recovery time doubles at most this many times over (a path late
/// for good retries the faster mode every few minutes, not every seconds).
const MAX_RECOVER_FACTOR: u32 = 16;
/// The window the incident rate is given over.
const RATE_WINDOW: Duration = Duration::from_secs(10);
/// A lost reply is evidence if its device answers again within this.
const LOST_CONFIRM: Duration = Duration::from_secs(1);
/// One poll transfer in this many is a sentinel (pipelined, it costs the
/// frame held for it: 1 in 49 of the bound; about 20 a second, so the
/// late path of the goals shows in about a second).
pub(crate) const SENTINEL_EVERY: u32 = 24;
/// How far before its boundary a sentinel is aimed, as a share of the frame.
pub(crate) const SENTINEL_LEAD: f64 = 0.1;
/// A sentinel handed over closer than this to its boundary (the host woke
/// late) and late says nothing of the path (on time, it still counts).
pub(crate) const SENTINEL_MIN_MARGIN: Duration = Duration::from_micros(60);
/// Sentinels late out of the last ones that make evidence (a host that
/// reads a reply late now and then makes one look late; three in a row
/// of 32 it does not).
const SENTINEL_SLIPS: usize = 3;
const SENTINEL_WINDOW: usize = 32;

/// What collisions leave behind, as the bus owner sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Evidence {
    /// Bytes that made no frame: CRC errors and bytes skipped.
    Garbled { bytes: u64 },
    /// A device's reply was missing (or matched after its deadline), and
    /// the device answers again.
    ReplyLost { dev_id: u8 },
    /// Sentinels whose write reached the adapter after their margin.
    LateSentinels { late: usize, of: usize },
    /// A confirmed write the port still counted as not taken this long
    /// after its boundary: the count cannot be trusted, or the adapter
    /// stopped taking bytes.
    Untaken { after: Duration },
}

impl fmt::Display for Evidence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Garbled { bytes } => {
                write!(f, "{bytes} garbled (CRC errors and bytes skipped)")
            }
            Self::ReplyLost { dev_id } => {
                write!(f, "a reply of device {dev_id} lost while it still answers")
            }
            Self::Untaken { after } => {
                write!(
                    f,
                    "a write not taken by the adapter {} ms after its USB frame (the port's output count)",
                    after.as_millis()
                )
            }
            Self::LateSentinels { late, of } => {
                write!(
                    f,
                    "{late} of the last {of} sentinel writes reached the adapter a frame late"
                )
            }
        }
    }
}

/// A change of mode, to publish and log once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Change {
    pub from: PipelineMode,
    pub to: PipelineMode,
    /// A step away from the bound (from `guarded` to `guarded` when its
    /// guard widens).
    pub backed_off: bool,
    pub reason: String,
}

/// What the bus view shows of the pipeline.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct UsbPipelineView {
    pub mode: PipelineMode,
    /// How late a write may reach the adapter and still leave where the
    /// wire is held for it, µs.
    pub guard_us: u64,
    /// How far before its USB frame boundary a write is aimed, µs.
    pub lead_us: u64,
    /// Why the mode last changed (`start` until it has).
    pub reason: String,
    /// Seconds since that change.
    pub since_s: f64,
    /// Incidents (evidence of a collision) per second over the last 10 s.
    pub incidents_per_s: f64,
    /// How long the mode must stay clean before stepping down, ms.
    pub recover_after_ms: u64,
    /// Steps up and down since start.
    pub backoffs: u64,
    pub recoveries: u64,
    /// Writes seen to reach the adapter a frame late while backed off
    /// (harmless then; each restarts the clean time).
    pub late_writes: u64,
    /// Sentinel transfers (written a tenth of a frame before their
    /// boundary, the wire held a frame longer) whose reply was matched,
    /// and those of them that reached the adapter a frame late.
    pub sentinels: u64,
    pub sentinels_late: u64,
    /// Writes are confirmed: the port says when the adapter took each,
    /// and the wire is held as it says, not for a write's reach.
    pub confirming: bool,
    /// Confirmed writes seen taken half a frame or more after the boundary
    /// they were aimed at (each held the wire that much longer, no
    /// collision): late writes, and looks the owner made late.
    pub writes_taken_late: u64,
    /// Confirmed writes whose output count stayed up
    /// for 4 ms after their USB frame (evidence: the count is not trusted).
    pub counts_given_up: u64,
    /// How late the bus thread wakes (a high quantile, measured on its
    /// timed waits), µs: the frame clock learnt from reply arrivals may run
    /// this much behind the adapter's, and each write spares it before
    /// its boundary.
    pub arrival_lag_us: u64,
}

/// The self-protection state of one latent bus.
#[derive(Debug, Clone)]
pub(crate) struct UsbGuard {
    mode: PipelineMode,
    /// In `guarded`: held for [`WIDE_GUARDED_REACH`], not [`GUARDED_REACH`].
    widened: bool,
    changed_at: Instant,
    reason: String,
    /// Since when nothing happened: the last change, incident or forgetting
    /// of a relapse.
    clean_from: Instant,
    /// The last step down, while a relapse would double the recovery time.
    stepped_down_at: Option<Instant>,
    recover_base: Duration,
    recover_factor: u32,
    incidents: VecDeque<Instant>,
    /// Garbled bytes seen so far (the link's running total).
    garbled_seen: u64,
    /// Garbage right after the port opened is the reconnect's, not a collision's.
    ignore_until: Option<Instant>,
    /// Devices whose reply went missing, and when.
    missed: Vec<(u8, Instant)>,
    backoffs: u64,
    recoveries: u64,
    late_writes: u64,
    /// Whether each of the last sentinels was late (pipelined only).
    sentinel_window: VecDeque<bool>,
    sentinels: u64,
    sentinels_late: u64,
    /// Of those, not yet handed to the bus counters.
    sentinels_untaken: (u64, u64),
    /// The ladder goes through `guarded`: only where waiting for a reply
    /// costs more than guarded's held frame (see [`Self::new`]).
    guarded_step: bool,
}

impl UsbGuard {
    /// `replies_next_frame`: the adapter hands a reply to the host in the
    /// USB frame after it left the wire (no latency timer). Then `lockstep`
    /// with a control-only transfer before each poll costs no more than
    /// `guarded` (a poll's transfer, its reply seen at the next frame and
    /// the next write leaving at the frame after: the 3 frames guarded
    /// holds) and no delay can make it collide, so the ladder skips
    /// `guarded`. Behind a latency timer a reply takes a millisecond or
    /// more to come back, and `guarded`'s blind writes keep the rates.
    pub(crate) fn new(recover: Duration, replies_next_frame: bool, now: Instant) -> Self {
        Self {
            guarded_step: !replies_next_frame,
            mode: PipelineMode::Pipelined,
            widened: false,
            changed_at: now,
            reason: "start".into(),
            clean_from: now,
            stepped_down_at: None,
            recover_base: recover.max(Duration::from_millis(1)),
            recover_factor: 1,
            incidents: VecDeque::new(),
            garbled_seen: 0,
            ignore_until: None,
            missed: Vec::new(),
            backoffs: 0,
            recoveries: 0,
            late_writes: 0,
            sentinel_window: VecDeque::with_capacity(SENTINEL_WINDOW),
            sentinels: 0,
            sentinels_late: 0,
            sentinels_untaken: (0, 0),
        }
    }

    /// Sentinels answered, and late, since the last call.
    pub(crate) fn take_sentinel_counts(&mut self) -> (u64, u64) {
        std::mem::take(&mut self.sentinels_untaken)
    }

    /// A sentinel's reply came, `late` or not. Enough late ones are
    /// evidence when pipelined, and keep a backed-off mode from stepping
    /// down (one alone may be the host: a thread preempted between
    /// dating a write and making it).
    pub(crate) fn sentinel(&mut self, late: bool, now: Instant) -> Option<Change> {
        self.sentinels += 1;
        self.sentinels_late += u64::from(late);
        self.sentinels_untaken.0 += 1;
        self.sentinels_untaken.1 += u64::from(late);
        if self.sentinel_window.len() == SENTINEL_WINDOW {
            self.sentinel_window.pop_front();
        }
        self.sentinel_window.push_back(late);
        let count = self.sentinel_window.iter().filter(|l| **l).count();
        if !late || count < SENTINEL_SLIPS {
            return None;
        }
        if self.mode != PipelineMode::Pipelined {
            self.clean_from = now;
            return None;
        }
        let of = self.sentinel_window.len();
        self.sentinel_window.clear();
        self.incident(Evidence::LateSentinels { late: count, of }, now)
    }

    /// A write was seen to reach the adapter a frame late (its reply came
    /// a frame after it would have). Backed off, that is no collision, but
    /// it says the path is still late: the mode is not clean. (Pipelined,
    /// the collision it makes is the evidence.)
    pub(crate) fn write_seen_late(&mut self, now: Instant) {
        if self.mode != PipelineMode::Pipelined {
            self.late_writes += 1;
            self.clean_from = now;
        }
    }

    pub(crate) fn mode(&self) -> PipelineMode {
        self.mode
    }

    /// True while polls are written blind (every mode but `lockstep`).
    pub(crate) fn blind(&self) -> bool {
        self.mode != PipelineMode::Lockstep
    }

    /// True when control-only transfers go between polls (each poll costs
    /// a held frame; a transfer without one keeps control at its rate).
    pub(crate) fn control_between_polls(&self) -> bool {
        self.mode != PipelineMode::Pipelined
    }

    /// How many frames late a write may leave into a wire held for it
    /// (one; two in the widened guard): a reply that late says its write
    /// slipped, harmlessly, and the path is still late.
    pub(crate) fn frames_of_slack(&self) -> u32 {
        if self.mode == PipelineMode::Guarded && self.widened {
            2
        } else {
            1
        }
    }

    /// How late a write may reach the adapter and still leave where the
    /// wire is held for it.
    pub(crate) fn reach(&self) -> Duration {
        match self.mode {
            PipelineMode::Pipelined => PIPELINED_REACH,
            PipelineMode::Guarded if self.widened => WIDE_GUARDED_REACH,
            PipelineMode::Guarded => GUARDED_REACH,
            PipelineMode::Lockstep => LOCKSTEP_REACH,
        }
    }

    /// How far before its boundary a write is aimed, as a share of the frame.
    pub(crate) fn lead(&self) -> f64 {
        match self.mode {
            PipelineMode::Pipelined => PIPELINED_LEAD,
            PipelineMode::Guarded | PipelineMode::Lockstep => GUARDED_LEAD,
        }
    }

    fn recover_after(&self) -> Duration {
        self.recover_base * self.recover_factor
    }

    /// The link's running total of garbled bytes is `total` at `now`.
    pub(crate) fn garbled_total(&mut self, total: u64, now: Instant) -> Option<Change> {
        let new = total.saturating_sub(self.garbled_seen);
        self.garbled_seen = total;
        if self.ignore_until.is_some_and(|until| now < until) {
            return None;
        }
        (new > 0).then(|| self.incident(Evidence::Garbled { bytes: new }, now))?
    }

    /// A poll of `dev_id` got no reply by its deadline.
    pub(crate) fn reply_missing(&mut self, dev_id: u8, now: Instant) {
        self.missed
            .retain(|(id, at)| *id != dev_id && now.duration_since(*at) < LOST_CONFIRM);
        self.missed.push((dev_id, now));
    }

    /// `dev_id` answered at `now`: a reply it missed shortly before was
    /// lost on the way, not a device gone. Dated to the miss: a miss of a
    /// transfer written before the last change does not step again.
    pub(crate) fn answered(&mut self, dev_id: u8, now: Instant) -> Option<Change> {
        if self.missed.is_empty() {
            return None;
        }
        let missed_at = self
            .missed
            .iter()
            .filter(|(id, at)| *id == dev_id && now.saturating_duration_since(*at) < LOST_CONFIRM)
            .map(|(_, at)| *at)
            .min();
        self.missed
            .retain(|(id, at)| *id != dev_id && now.saturating_duration_since(*at) < LOST_CONFIRM);
        let at = missed_at?;
        self.incident_at(Evidence::ReplyLost { dev_id }, at, now)
    }

    /// One piece of evidence at `now`: steps up unless it belongs to
    /// transfers written before the last change.
    pub(crate) fn incident(&mut self, evidence: Evidence, now: Instant) -> Option<Change> {
        self.incident_at(evidence, now, now)
    }

    /// Evidence that showed at `now` of what happened at `seen`.
    fn incident_at(&mut self, evidence: Evidence, seen: Instant, now: Instant) -> Option<Change> {
        self.incidents.push_back(now);
        self.prune(now);
        self.clean_from = now;
        if let Some(down) = self.stepped_down_at.take() {
            if now.saturating_duration_since(down) < self.recover_after() * 2 {
                self.recover_factor = (self.recover_factor * 2).min(MAX_RECOVER_FACTOR);
            }
        }
        if seen.saturating_duration_since(self.changed_at) < SETTLE {
            return None;
        }
        let (to, widened) = self.step_up()?;
        self.backoffs += 1;
        let reason = format!("backed off{}: {evidence}", Self::widening(widened, to));
        Some(self.change((to, widened), true, reason, now))
    }

    /// The next step up: behind a latency timer `guarded` widens before it
    /// gives way to `lockstep` (without one, `lockstep` is the cheaper).
    fn step_up(&self) -> Option<(PipelineMode, bool)> {
        match self.mode {
            PipelineMode::Guarded if !self.widened && self.guarded_step => {
                Some((PipelineMode::Guarded, true))
            }
            mode => mode.up(self.guarded_step).map(|to| (to, false)),
        }
    }

    /// The next step down: `lockstep` to the widened guard, which narrows
    /// before `pipelined`.
    fn step_down(&self) -> Option<(PipelineMode, bool)> {
        match self.mode {
            PipelineMode::Guarded if self.widened => Some((PipelineMode::Guarded, false)),
            mode => mode
                .down(self.guarded_step)
                .map(|to| (to, to == PipelineMode::Guarded)),
        }
    }

    /// What a change reason adds when it lands in `guarded`.
    fn widening(widened: bool, to: PipelineMode) -> String {
        match (to, widened) {
            (PipelineMode::Guarded, true) => {
                format!(" (guard widened to {} µs)", WIDE_GUARDED_REACH.as_micros())
            }
            (PipelineMode::Guarded, false) => {
                format!(" (guard {} µs)", GUARDED_REACH.as_micros())
            }
            _ => String::new(),
        }
    }

    /// Steps down one mode once the current one has been clean for the
    /// recovery time; at the bottom, forgets a relapse (halves the
    /// recovery time) per twice that clean.
    pub(crate) fn tick(&mut self, now: Instant) -> Option<Change> {
        let clean = now.saturating_duration_since(self.clean_from);
        let Some((to, widened)) = self.step_down() else {
            if self.recover_factor > 1 && clean >= self.recover_after() * 2 {
                self.recover_factor /= 2;
                self.clean_from = now;
            }
            return None;
        };
        if clean < self.recover_after() {
            return None;
        }
        self.recoveries += 1;
        self.stepped_down_at = Some(now);
        let reason = format!(
            "recovered{}: clean for {} ms",
            Self::widening(widened, to),
            clean.as_millis()
        );
        Some(self.change((to, widened), false, reason, now))
    }

    /// Whether the ladder goes through `guarded` (the adapter was named
    /// again, its latency timer perhaps changed).
    pub(crate) fn set_replies_next_frame(&mut self, on: bool) {
        self.guarded_step = !on;
    }

    fn change(
        &mut self,
        (to, widened): (PipelineMode, bool),
        backed_off: bool,
        reason: String,
        now: Instant,
    ) -> Change {
        let from = std::mem::replace(&mut self.mode, to);
        self.widened = widened;
        self.sentinel_window.clear();
        self.changed_at = now;
        self.clean_from = now;
        self.reason.clone_from(&reason);
        Change {
            from,
            to,
            backed_off,
            reason,
        }
    }

    fn prune(&mut self, now: Instant) {
        while self
            .incidents
            .front()
            .is_some_and(|at| now.saturating_duration_since(*at) > RATE_WINDOW)
        {
            self.incidents.pop_front();
        }
    }

    /// The port was (re)opened at `now`: the mode stays (a reconnect says
    /// nothing of the host's timing); what was missed before says nothing,
    /// nor does garbage while the line settles.
    pub(crate) fn link_up(&mut self, now: Instant) {
        self.missed.clear();
        self.ignore_until = Some(now + SETTLE);
    }

    pub(crate) fn view(&mut self, period: Duration, now: Instant) -> UsbPipelineView {
        self.prune(now);
        UsbPipelineView {
            mode: self.mode,
            guard_us: self.reach().as_micros() as u64,
            lead_us: period.mul_f64(self.lead()).as_micros() as u64,
            reason: self.reason.clone(),
            since_s: now.saturating_duration_since(self.changed_at).as_secs_f64(),
            incidents_per_s: self.incidents.len() as f64 / RATE_WINDOW.as_secs_f64(),
            recover_after_ms: self.recover_after().as_millis() as u64,
            backoffs: self.backoffs,
            recoveries: self.recoveries,
            late_writes: self.late_writes,
            sentinels: self.sentinels,
            sentinels_late: self.sentinels_late,
            confirming: false,
            writes_taken_late: 0,
            counts_given_up: 0,
            arrival_lag_us: 0,
        }
    }
}

#[cfg(test)]
#[path = "guard_tests.rs"]
mod tests;
