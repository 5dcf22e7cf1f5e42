//! The port's side of the schedule: up or down, when to try opening a lost
//! port again (backoff doubling to a cap, reset by success), and the quiet
//! spell after opening while powered-up devices announce themselves.
//!
//! Pure: every instant is passed in.

use std::time::{Duration, Instant};

/// First and longest wait between attempts to reopen a lost port.
pub(super) const BACKOFF_FIRST: Duration = Duration::from_millis(20);
pub(super) const BACKOFF_MAX: Duration = Duration::from_secs(1);
/// How long a freshly opened port is only listened to: devices powered up
/// with the daemon announce themselves (INFO_01) within a few ms, and a
/// frame written meanwhile would collide with their announcements. An
/// adapter holds them a while longer ([`Reopen::opened`]).
pub(super) const LISTEN_ON_OPEN: Duration = Duration::from_millis(20);

#[derive(Debug, Clone)]
pub(super) struct Reopen {
    up: bool,
    backoff: Duration,
    next_open: Instant,
    /// Nothing is written before this (the quiet spell after opening).
    quiet_until: Instant,
    ever_up: bool,
}

impl Reopen {
    /// A port not opened yet: the first attempt is due at once.
    pub(super) fn new(now: Instant) -> Self {
        Self {
            up: false,
            backoff: BACKOFF_FIRST,
            next_open: now,
            quiet_until: now,
            ever_up: false,
        }
    }

    pub(super) fn is_up(&self) -> bool {
        self.up
    }

    pub(super) fn next_open(&self) -> Instant {
        self.next_open
    }

    pub(super) fn quiet_until(&self) -> Instant {
        self.quiet_until
    }

    /// The port opened at `now`, behind an adapter that may hold a reply
    /// for `hold` before the host reads it; true when it had been up before
    /// (a reconnect). The quiet spell lasts until the announcements are
    /// read: a device polled while its announcement is still in the
    /// adapter answers with a frame just like it, read after it, and only
    /// the order of the bytes tells them apart.
    pub(super) fn opened(&mut self, now: Instant, hold: Duration) -> bool {
        let again = self.ever_up;
        self.up = true;
        self.ever_up = true;
        self.backoff = BACKOFF_FIRST;
        self.quiet_until = now + LISTEN_ON_OPEN + hold;
        again
    }

    /// An attempt failed at `now`; returns the wait before the next one.
    pub(super) fn open_failed(&mut self, now: Instant) -> Duration {
        let retry = self.backoff;
        self.next_open = now + retry;
        self.backoff = (self.backoff * 2).min(BACKOFF_MAX);
        retry
    }

    /// The port was lost at `now`: the first retry comes soon.
    pub(super) fn lost(&mut self, now: Instant) -> Duration {
        self.up = false;
        self.backoff = BACKOFF_FIRST;
        self.next_open = now + BACKOFF_FIRST;
        BACKOFF_FIRST
    }
}
