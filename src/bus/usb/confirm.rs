//! Confirmed writes: behind a USB adapter whose port says when the adapter
//! took a write, no write is taken on trust.
//!
//! A USB-serial driver counts the bytes it holds until the adapter takes
//! them (`TIOCOUTQ`: its buffer and the transfer in flight, which completes
//! at the USB frame the bytes leave in). So the owner writes a poll's
//! transfer aimed at boundary `b`, with the wire held as if it leaves
//! there, and writes nothing else until the count says the adapter took
//! it. It looks shortly after `b` ([`CHECK_AFTER`] of a frame): taken, the
//! write left by then, and the wire model holds from the moment of the
//! look (a little later than `b`, never earlier than the truth, whatever
//! the frame clock's error); not taken, it leaves at a later boundary, and
//! the owner looks again after the next. A late write then costs the
//! frames it was late, never a collision, and an on-time one costs the
//! look's lag, inside the guard the cycle already has: the pipeline keeps
//! the adapter's bound on a path whose writes come late now and then,
//! where blind writes must hold a frame after every poll for the one that
//! might (see [`super::guard`]).
//!
//! A count that stays up for [`MAX_UNTAKEN`] (an adapter slow to take
//! bytes, a host too loaded to let it) is counted as given up on, and the
//! write is still waited for: anything written behind it would queue in
//! the adapter and follow it onto the wire into its reply, and blind
//! writes would do worse on such a path. Only an e-stop goes behind an
//! overdue write (it can only queue there, and must not wait). A count
//! still up [`MAX_WAITED`] after the boundary is taken for a count that
//! lies (a driver whose count does not fall): it is no longer waited for,
//! and the pipeline's guard backs off to blind writes.
//!
//! What it tolerates: any lateness of the owner. A look made late holds
//! the wire from the look; a write made late is seen untaken and moved;
//! without a frame clock (a host too busy to learn it) the owner looks a
//! few times a frame and holds the wire from the look that saw the take.
//! A write untaken for [`MAX_UNTAKEN`] is counted, and nothing but an
//! e-stop is written until it is taken; only past [`MAX_WAITED`] does the
//! pipeline back off.
//!
//! Pure: every instant is passed in.

use std::time::{Duration, Instant};

/// How long after the boundary a write is aimed at the count is read, as a
/// share of the frame: the adapter's taking of a write shows in the
/// driver's count within this (the model shows it at once). A look later
/// than the cycle's guard allows costs a frame, not a collision.
pub(crate) const CHECK_AFTER: f64 = 0.15;
/// How long after the boundary it was aimed at a write may stay untaken
/// before the count is given up on: four full-speed USB frames.
pub(crate) const MAX_UNTAKEN: Duration = Duration::from_millis(4);
/// How long before the boundary a write is aimed at the count is read
/// once, where the write leaves time for it, as a share of the frame:
/// still untaken there, the frame clock's estimate held for this write;
/// taken already, the estimate is off (see [`Outcome::TakenEarly`]).
pub(crate) const EARLY_LOOK: f64 = 0.1;
/// How long after its boundary an untaken write is waited for at all: a
/// count up this long says nothing of the adapter any more.
pub(crate) const MAX_WAITED: Duration = Duration::from_millis(50);

/// The write waiting to be confirmed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Pending {
    /// The boundary it was aimed at.
    first: Instant,
    /// The boundary after which the count is read next.
    frame: Instant,
    /// When the wire model has it leave.
    modeled: Instant,
    /// It carried a poll (the newest in flight).
    poll: bool,
    /// Untaken past [`MAX_UNTAKEN`]: given up on as evidence, still waited for.
    overdue: bool,
    /// Aimed by the frame clock (not held as late as an unclocked write
    /// may leave): a take before `first` says the clock is off.
    clocked: bool,
    /// When to read the count once before `first` (see [`EARLY_LOOK`]).
    early: Option<Instant>,
    /// How long before `first` the write was made.
    lead: Duration,
}

/// What a look at the count found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Outcome {
    /// Nothing to confirm, or too early to tell.
    Wait,
    /// Untaken shortly before the boundary it was aimed at, as the frame
    /// clock says it should be, for a write made `lead` before that
    /// boundary: no boundary lay between the two.
    OnClock { lead: Duration },
    /// Taken before the boundary the frame clock had it leave at: the
    /// clock's estimate is off (a host that reads replies late learns it
    /// late), and a write made early in a frame may leave a frame early.
    /// The wire model keeps it at the later boundary (later than the truth).
    TakenEarly { poll: bool },
    /// Taken by the look: the wire model moves `by` (zero when the model
    /// already had it leave at or after the look).
    Taken { by: Duration, poll: bool },
    /// Not taken by the look: it leaves after the next boundary at the
    /// earliest, `by` later than the model had.
    Moved { by: Duration, poll: bool },
    /// Untaken for [`MAX_UNTAKEN`]: evidence for the guard, reported
    /// once; it leaves after the next boundary at the earliest, `by` later
    /// than the model had, and is still waited for.
    GaveUp { by: Duration, poll: bool },
    /// Untaken for [`MAX_WAITED`]: the count is not believed; taken to
    /// leave at the next boundary and no longer waited for.
    Abandoned { by: Duration, poll: bool },
}

/// The one write the owner waits to see taken.
#[derive(Debug, Clone, Default)]
pub(crate) struct Confirm {
    pending: Option<Pending>,
    /// Writes seen taken half a frame or more after the boundary they were
    /// aimed at (each cost the frames it was late, no collision).
    pub late: u64,
    /// Writes whose count stayed up for [`MAX_UNTAKEN`].
    pub gave_up: u64,
    /// Writes seen taken before the boundary the frame clock aimed them at.
    pub early_takes: u64,
    /// Of those, not yet handed to the bus counters: (late, given up).
    untaken: (u64, u64),
}

impl Confirm {
    /// A write was handed over `lead` before `boundary`, the first after it
    /// by the frame clock, where the wire model has it leave; `early`, when
    /// to check the clock on it before then.
    pub(crate) fn written(&mut self, boundary: Instant, lead: Duration, early: Option<Instant>) {
        self.pending = Some(Pending {
            first: boundary,
            frame: boundary,
            modeled: boundary,
            poll: false,
            overdue: false,
            clocked: true,
            early,
            lead,
        });
    }

    /// A write was handed over with no frame clock: the wire model has it
    /// leave at `latest`, the latest it may.
    pub(crate) fn written_unclocked(&mut self, latest: Instant) {
        self.written(latest, Duration::ZERO, None);
        if let Some(p) = self.pending.as_mut() {
            p.clocked = false;
        }
    }

    /// The write just made carried a poll.
    pub(crate) fn carried_poll(&mut self) {
        if let Some(p) = self.pending.as_mut() {
            p.poll = true;
        }
    }

    pub(crate) fn waiting(&self) -> bool {
        self.pending.is_some()
    }

    /// True while the write waited for is untaken past [`MAX_UNTAKEN`]:
    /// an e-stop may go behind it.
    pub(crate) fn overdue(&self) -> bool {
        self.pending.is_some_and(|p| p.overdue)
    }

    /// When to read the count next.
    pub(crate) fn check_at(&self, period: Duration) -> Option<Instant> {
        let p = self.pending?;
        Some(p.early.unwrap_or(p.frame + period.mul_f64(CHECK_AFTER)))
    }

    /// The count read `unsent`, timed `now` after the read (`None`: the
    /// port cannot tell any more, as after a reopen: nothing to wait for).
    /// `boundary_after` gives the first USB frame boundary after an instant.
    pub(crate) fn look(
        &mut self,
        unsent: Option<usize>,
        now: Instant,
        period: Duration,
        boundary_after: impl Fn(Instant) -> Instant,
    ) -> Outcome {
        let Some(mut p) = self.pending else {
            return Outcome::Wait;
        };
        match unsent {
            None => {
                self.pending = None;
                Outcome::Taken {
                    by: Duration::ZERO,
                    poll: p.poll,
                }
            }
            Some(0) if p.clocked && now < p.first => {
                self.pending = None;
                self.early_takes += 1;
                Outcome::TakenEarly { poll: p.poll }
            }
            Some(0) => {
                self.pending = None;
                // Taken by now: the wire is held from now at the latest.
                let late = u64::from(now >= p.first + period / 2);
                self.late += late;
                self.untaken.0 += late;
                Outcome::Taken {
                    by: now.saturating_duration_since(p.modeled),
                    poll: p.poll,
                }
            }
            Some(_) => {
                if p.early.is_some_and(|early| now >= early) {
                    p.early = None;
                    self.pending = Some(p);
                    if now < p.first {
                        return Outcome::OnClock { lead: p.lead };
                    }
                }
                if now < p.frame + period.mul_f64(CHECK_AFTER) {
                    return Outcome::Wait;
                }
                let next = boundary_after(now);
                let by = next.saturating_duration_since(p.modeled);
                let untaken = next.saturating_duration_since(p.first);
                if untaken >= MAX_WAITED {
                    self.pending = None;
                    return Outcome::Abandoned { by, poll: p.poll };
                }
                p.frame = next;
                p.modeled = p.modeled.max(next);
                let gave_up = untaken >= MAX_UNTAKEN && !p.overdue;
                p.overdue |= gave_up;
                self.pending = Some(p);
                if gave_up {
                    self.gave_up += 1;
                    self.untaken.1 += 1;
                    return Outcome::GaveUp { by, poll: p.poll };
                }
                Outcome::Moved { by, poll: p.poll }
            }
        }
    }

    /// Writes seen taken late, and counts given up on, since the last call.
    pub(crate) fn take_counts(&mut self) -> (u64, u64) {
        std::mem::take(&mut self.untaken)
    }

    /// The port was lost or reopened, or the write was waited for: nothing
    /// waits.
    pub(crate) fn reset(&mut self) {
        self.pending = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: Duration = Duration::from_millis(1);

    fn us(n: u64) -> Duration {
        Duration::from_micros(n)
    }

    /// Boundaries every millisecond from `t0`.
    fn after(t0: Instant) -> impl Fn(Instant) -> Instant {
        move |t| {
            let into = t.duration_since(t0).as_nanos() % P.as_nanos();
            t + Duration::from_nanos((P.as_nanos() - into) as u64)
        }
    }

    #[test]
    fn a_write_taken_by_the_look_holds_the_wire_from_the_look() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        c.carried_poll();
        assert_eq!(c.check_at(P), Some(t0 + us(1_150)));
        assert_eq!(c.look(Some(40), t0 + us(900), P, after(t0)), Outcome::Wait);
        assert_eq!(
            c.look(Some(0), t0 + us(1_160), P, after(t0)),
            Outcome::Taken {
                by: us(160),
                poll: true
            }
        );
        assert!(!c.waiting());
        assert_eq!(c.late, 0);
    }

    #[test]
    fn a_write_taken_before_its_boundary_says_the_clock_is_off() {
        // The frame clock's estimate late: the count shows the write taken
        // before the boundary the model has, which stays (later than the
        // truth: nothing moves).
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), Some(t0 + us(900)));
        assert_eq!(c.check_at(P), Some(t0 + us(900)));
        assert_eq!(
            c.look(Some(0), t0 + us(900), P, after(t0)),
            Outcome::TakenEarly { poll: false }
        );
        assert!(!c.waiting());
        assert_eq!(c.early_takes, 1);
    }

    #[test]
    fn a_write_untaken_just_before_its_boundary_is_on_the_clock() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), Some(t0 + us(900)));
        // A look before the early one says nothing yet.
        assert_eq!(c.look(Some(40), t0 + us(500), P, after(t0)), Outcome::Wait);
        assert_eq!(
            c.look(Some(40), t0 + us(905), P, after(t0)),
            Outcome::OnClock { lead: us(300) }
        );
        // Then the regular look.
        assert_eq!(c.check_at(P), Some(t0 + us(1_150)));
        assert_eq!(
            c.look(Some(0), t0 + us(1_150), P, after(t0)),
            Outcome::Taken {
                by: us(150),
                poll: false
            }
        );
    }

    #[test]
    fn an_unclocked_write_taken_before_its_latest_is_no_clock_error() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written_unclocked(t0 + us(1_200));
        assert_eq!(
            c.look(Some(0), t0 + us(1_000), P, after(t0)),
            Outcome::Taken {
                by: Duration::ZERO,
                poll: false
            }
        );
        assert_eq!(c.early_takes, 0);
    }

    #[test]
    fn a_write_untaken_at_the_look_moves_past_the_next_boundary() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        let moved = c.look(Some(60), t0 + us(1_150), P, after(t0));
        assert_eq!(moved, Outcome::Moved { by: P, poll: false });
        assert_eq!(c.check_at(P), Some(t0 + us(2_150)));
        assert_eq!(
            c.look(Some(60), t0 + us(2_000), P, after(t0)),
            Outcome::Wait
        );
        assert_eq!(
            c.look(Some(0), t0 + us(2_200), P, after(t0)),
            Outcome::Taken {
                by: us(200),
                poll: false
            }
        );
        assert_eq!(c.late, 1);
    }

    #[test]
    fn a_look_long_after_the_boundary_holds_the_wire_from_the_look() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        // The host looked only at 2.3 ms: it left by then, when is unknown.
        assert_eq!(
            c.look(Some(0), t0 + us(2_300), P, after(t0)),
            Outcome::Taken {
                by: us(1_300),
                poll: false
            }
        );
        // Untaken at 2.3 ms: it leaves at 3 ms at the earliest.
        c.written(t0 + P, us(300), None);
        assert_eq!(
            c.look(Some(20), t0 + us(2_300), P, after(t0)),
            Outcome::Moved {
                by: P * 2,
                poll: false
            }
        );
    }

    #[test]
    fn a_count_that_stays_up_is_given_up_on() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        let mut outcomes = Vec::new();
        for k in 1..=6u64 {
            let at = t0 + us(1_000 * k + 200);
            outcomes.push(c.look(Some(60), at, P, after(t0)));
        }
        assert_eq!(
            outcomes,
            [
                Outcome::Moved { by: P, poll: false },
                Outcome::Moved { by: P, poll: false },
                Outcome::Moved { by: P, poll: false },
                Outcome::GaveUp { by: P, poll: false },
                Outcome::Moved { by: P, poll: false },
                Outcome::Moved { by: P, poll: false },
            ]
        );
        assert_eq!(c.gave_up, 1);
        // Still waited for: whatever is written behind it follows it out.
        assert!(c.waiting() && c.overdue());
        assert_eq!(
            c.look(Some(0), t0 + us(7_300), P, after(t0)),
            Outcome::Taken {
                by: us(300),
                poll: false
            }
        );
        assert!(!c.waiting() && !c.overdue());
    }

    #[test]
    fn a_count_up_past_the_longest_wait_is_not_believed() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        let mut last = Outcome::Wait;
        for k in 1..=60u64 {
            last = c.look(Some(60), t0 + us(1_000 * k + 200), P, after(t0));
            if !c.waiting() {
                break;
            }
        }
        assert_eq!(last, Outcome::Abandoned { by: P, poll: false });
        assert_eq!(c.gave_up, 1, "counted once, when it became overdue");
    }

    #[test]
    fn a_port_that_cannot_tell_ends_the_wait() {
        let t0 = Instant::now();
        let mut c = Confirm::default();
        c.written(t0 + P, us(300), None);
        assert!(matches!(
            c.look(None, t0 + us(100), P, after(t0)),
            Outcome::Taken { .. }
        ));
        assert!(!c.waiting());
        assert_eq!(c.look(Some(0), t0, P, after(t0)), Outcome::Wait);
    }
}
