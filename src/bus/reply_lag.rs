//! How long after the line model's due time a reply reaches the host: a
//! low quantile of that lag, so the owner starts watching the port where
//! replies come, not where the model puts them.
//!
//! On a native UART the lag is a few µs. A pty, or a USB adapter's path
//! beyond what its model holds, adds tens of µs to every reply, and the
//! owner, awake from just before the modelled time, would spin through all
//! of it on every poll: most of its CPU on such a line. Aiming at a low
//! quantile keeps the owner awake before nearly every reply (the line does
//! not idle while it wakes) and spins only through the spread above it.
//!
//! Only a reply the owner was already watching for gives its arrival
//! exactly. One found at the first look, or one that woke the thread, may
//! have come earlier: such a time bounds the arrival from above and may
//! only lower the estimate. Raising it on those would chase the owner's
//! own lateness: a later look finds more replies waiting, which would say
//! to look later still.

use std::time::{Duration, Instant};

use crate::rt::skewed::Skewed;

/// The most lag the owner aims past: beyond it a reply is late, not a
/// path's steady lag, and the owner waits for it asleep.
pub(crate) const MAX_LAG: Duration = Duration::from_micros(500);

/// Weight of a sample below the estimate (falls fast).
const FALL: f64 = 0.25;
/// Weight of a sample above the estimate (rises slowly). With these two
/// the estimate settles low in the spread: for lags spread evenly, about a
/// fifth of the replies come sooner.
const RISE: f64 = 0.02;

/// How the owner came to see a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Seen {
    /// While it watched the port and had found it empty: the arrival.
    Watching,
    /// At its first look, or on being woken by it: at or after the arrival.
    Bound,
}

#[derive(Debug, Clone)]
pub(crate) struct ReplyLag {
    estimate: Skewed,
}

impl Default for ReplyLag {
    fn default() -> Self {
        Self {
            estimate: Skewed::new(Duration::ZERO, RISE, FALL),
        }
    }
}

impl ReplyLag {
    /// How long after its modelled time a reply is expected, at the least.
    pub(crate) fn lag(&self) -> Duration {
        self.estimate.get().min(MAX_LAG)
    }

    /// A reply modelled at `due` was seen at `seen_at`.
    pub(crate) fn observe(&mut self, due: Instant, seen_at: Instant, seen: Seen) {
        let lag = seen_at.saturating_duration_since(due).min(MAX_LAG);
        match seen {
            Seen::Watching => self.estimate.feed(lag),
            Seen::Bound => self.estimate.feed_if_lower(lag),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(l: &mut ReplyLag, lags_us: &[u64], seen: Seen) {
        let t0 = Instant::now();
        for us in lags_us {
            l.observe(t0, t0 + Duration::from_micros(*us), seen);
        }
    }

    #[test]
    fn starts_at_the_model() {
        assert_eq!(ReplyLag::default().lag(), Duration::ZERO);
    }

    #[test]
    fn settles_below_most_of_a_steady_lag() {
        // A pty-like path: every reply 30–70 µs after the model.
        let mut l = ReplyLag::default();
        let lags: Vec<u64> = (0..2000).map(|i| 30 + (i * 37) % 41).collect();
        feed(&mut l, &lags, Seen::Watching);
        let lag = l.lag().as_micros() as u64;
        assert!((30..=45).contains(&lag), "{lag} µs");
        let below = lags.iter().filter(|&&x| x < lag).count();
        assert!(
            below * 100 < lags.len() * 30,
            "{below} of {} below",
            lags.len()
        );
    }

    #[test]
    fn a_quicker_path_is_followed_at_once() {
        let mut l = ReplyLag::default();
        feed(&mut l, &[100; 500], Seen::Watching);
        feed(&mut l, &[5; 20], Seen::Watching);
        assert!(l.lag() < Duration::from_micros(10), "{:?}", l.lag());
    }

    #[test]
    fn a_reply_found_waiting_never_raises_it() {
        let mut l = ReplyLag::default();
        feed(&mut l, &[40; 500], Seen::Watching);
        let before = l.lag();
        feed(&mut l, &[300; 500], Seen::Bound);
        assert_eq!(l.lag(), before);
        // ... but says the path got quicker.
        feed(&mut l, &[0; 50], Seen::Bound);
        assert!(l.lag() < Duration::from_micros(2), "{:?}", l.lag());
    }

    #[test]
    fn a_stall_is_not_aimed_past() {
        let mut l = ReplyLag::default();
        feed(&mut l, &[20_000; 5000], Seen::Watching);
        assert_eq!(l.lag(), MAX_LAG);
    }
}
