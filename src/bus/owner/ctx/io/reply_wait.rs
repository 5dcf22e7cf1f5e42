//! How the owner waits for the reply to a request it wrote: asleep until
//! just before the reply is due, then looking at the port without sleeping
//! (a thread woken from sleep reacts tens of µs late), then in short
//! slices that give way to an e-stop until the deadline.

use std::time::{Duration, Instant};

use crate::bus::reply_lag::Seen;
use crate::bus::wire::{ReplyWindow, Want};
use crate::protocol::Reply;

use super::super::Ctx;

/// With `reply_spin_us = 0` (no spinning): how long before a reply is due
/// the owner wakes to plan the next control frame: ample for planning,
/// short enough that the setpoints it samples are fresh.
const PREPARE_LEAD: Duration = Duration::from_micros(100);
/// How often a reply wait past its modelled time looks for an e-stop.
const LATE_WAIT_SLICE: Duration = Duration::from_millis(1);

impl Ctx {
    /// From when a wait for the reply to a request ending at `end` goes in
    /// short slices that give way to an e-stop: a frame after the modelled
    /// reply, or from the e-stop cut-in (the reply off the wire, held by a
    /// latency timer) if that is sooner. A late, missing or held reply must
    /// not hold an e-stop back, nor the snapshot; nor may the owner's aim
    /// at where replies have been coming (up to
    /// [`crate::bus::reply_lag::MAX_LAG`] past the model).
    pub(super) fn sliced_from(&self, window: ReplyWindow, end: Instant) -> Instant {
        let grace = window.due + self.sched.clock().frame_time();
        self.sched.estop_cut_in(end).map_or(grace, |c| c.min(grace))
    }

    /// Waits for `want` until the window's deadline, watching the port from
    /// `aim` (the modelled time plus the lag replies have shown); in
    /// slices from `sliced_from` (see [`Self::sliced_from`]). Says whether
    /// the reply came while the port was watched.
    pub(super) fn wait_reply(
        &mut self,
        want: Want,
        window: ReplyWindow,
        aim: Instant,
        sliced_from: Instant,
    ) -> (std::io::Result<Option<(Reply, Instant)>>, Seen) {
        if self.estop_pending() && Instant::now() >= sliced_from {
            return (Ok(None), Seen::Bound);
        }
        let (mut got, mut seen) = self.spin_for_reply(want, aim, sliced_from);
        if matches!(got, Ok(None)) {
            // A reply from here on wakes the thread: it may have come
            // before it was read.
            seen = Seen::Bound;
            got = self.link.wait(Some(want), sliced_from.min(window.deadline));
        }
        (self.wait_sliced(want, got, window.deadline, true), seen)
    }

    /// Goes on waiting for `want` until `until` while `got` is empty, in
    /// slices of [`LATE_WAIT_SLICE`] that give way to an e-stop; with
    /// `housekeeping`, the snapshot and expiries are kept up between them.
    pub(super) fn wait_sliced(
        &mut self,
        want: Want,
        mut got: std::io::Result<Option<(Reply, Instant)>>,
        until: Instant,
        housekeeping: bool,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        while matches!(got, Ok(None)) && !self.estop_pending() {
            let now = Instant::now();
            if now >= until {
                break;
            }
            if housekeeping {
                self.housekeeping(now);
            }
            got = self.link.wait(Some(want), until.min(now + LATE_WAIT_SLICE));
        }
        got
    }

    /// Blocks until shortly before `due`, where the reply is expected: by
    /// as much as this thread is seen to wake late (learnt by the link from
    /// every timed read), when it spins for the reply next
    /// ([`Self::spin_for_reply`]); by [`PREPARE_LEAD`] when it does not.
    /// Past `sliced_from` (see [`Self::sliced_from`]) it sleeps in short
    /// slices and gives way to an e-stop.
    pub(super) fn sleep_before_reply(
        &mut self,
        want: Want,
        due: Instant,
        sliced_from: Instant,
    ) -> std::io::Result<Option<(Reply, Instant)>> {
        let lead = if self.cfg.timing.reply_spin_us > 0 {
            self.link.wake_lateness()
        } else {
            PREPARE_LEAD
        };
        let until = due.checked_sub(lead).unwrap_or(due);
        let got = self.link.wait(Some(want), sliced_from.min(until));
        self.wait_sliced(want, got, until, false)
    }

    /// Looks at the port without sleeping until `reply_spin_us` past `aim`
    /// (where the reply is expected): a thread woken from sleep (on a VM, a
    /// halted virtual CPU woken too) reacts tens of µs later, and every
    /// poll's reply would be followed by such a gap on the line. A reply
    /// found after an empty look arrived when it was found. Past
    /// `sliced_from` it gives way to an e-stop.
    pub(super) fn spin_for_reply(
        &mut self,
        want: Want,
        aim: Instant,
        sliced_from: Instant,
    ) -> (std::io::Result<Option<(Reply, Instant)>>, Seen) {
        let spin = Duration::from_micros(self.cfg.timing.reply_spin_us);
        if spin.is_zero() {
            return (Ok(None), Seen::Bound);
        }
        let mut got = self.link.poll_now(Some(want));
        let mut seen = Seen::Bound;
        while matches!(got, Ok(None)) {
            let now = Instant::now();
            if now >= aim + spin || (now >= sliced_from && self.estop_pending()) {
                break;
            }
            std::hint::spin_loop();
            seen = Seen::Watching;
            got = self.link.poll_now(Some(want));
        }
        (got, seen)
    }
}
