//! How often a cause may be said on `/rosout`: at most once per
//! [`EVERY`] per cause, so that a controller streaming the same bad
//! command at 100 Hz gives one warning, not a hundred a second, while a
//! new cause is said at once. Decided apart from any I/O, on the caller's
//! clock.

use std::collections::HashMap;
use std::time::{Duration, Instant};

/// The shortest time between two warnings of one cause.
pub(crate) const EVERY: Duration = Duration::from_secs(5);

/// When each cause was last said.
#[derive(Debug, Default)]
pub(crate) struct Throttle {
    said: HashMap<String, Instant>,
}

impl Throttle {
    /// Whether `cause` may be said at `now` (and, if so, that it was).
    pub(crate) fn allow(&mut self, cause: &str, now: Instant) -> bool {
        match self.said.get(cause) {
            Some(at) if now.saturating_duration_since(*at) < EVERY => false,
            _ => {
                self.said.insert(cause.to_owned(), now);
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_cause_is_said_once_per_five_seconds_and_others_at_once() {
        let t0 = Instant::now();
        let mut t = Throttle::default();
        assert!(t.allow("soft-limit", t0));
        assert!(!t.allow("soft-limit", t0 + Duration::from_millis(10)));
        assert!(t.allow("unknown-joint", t0 + Duration::from_millis(20)));
        assert!(!t.allow("soft-limit", t0 + Duration::from_millis(4_999)));
        assert!(t.allow("soft-limit", t0 + EVERY));
        assert!(!t.allow("soft-limit", t0 + EVERY + Duration::from_secs(1)));
        assert!(!t.allow("unknown-joint", t0 + Duration::from_secs(5)));
        assert!(t.allow("unknown-joint", t0 + Duration::from_millis(5_020)));
    }
}
