//! Collapsing repeated log lines, so a storm of identical failures (a
//! client retrying against a bus that is down) writes one line per window
//! and a count, not one line per request.
//!
//! [`Collapse::admit`] decides, the caller logs: the first line of a key in
//! a window goes out; the rest of that window are counted, and the next
//! line that goes out carries how many were held back ("and N more like it
//! in the last 10 s").

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Keys remembered at most; past it the table starts afresh (a burst of
/// distinct keys must not grow memory; at worst a few lines repeat).
const MAX_KEYS: usize = 256;

/// One window per key: when it opened and how many lines it held back.
#[derive(Debug)]
struct Window {
    opened: Instant,
    held: u64,
}

/// A per-key rate limit for log lines: one line per key per `window`.
#[derive(Debug)]
pub(crate) struct Collapse {
    window: Duration,
    // std Mutex: held only to look up a counter, never across an `.await`.
    keys: Mutex<HashMap<String, Window>>,
}

impl Collapse {
    pub(crate) fn new(window: Duration) -> Self {
        Self {
            window,
            keys: Mutex::new(HashMap::new()),
        }
    }

    /// The end of a line that went out after `held` were held back:
    /// empty when none were.
    pub(crate) fn held_note(&self, held: u64) -> String {
        match held {
            0 => String::new(),
            n => format!(
                " (and {n} more like it in the last {} s)",
                self.window.as_secs()
            ),
        }
    }

    /// `Some(held)` when a line for `key` should be logged now, `held` being
    /// how many were held back since the previous one; `None` to skip it.
    pub(crate) fn admit(&self, key: &str, now: Instant) -> Option<u64> {
        let mut keys = self.keys.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(w) = keys.get_mut(key) {
            if now.saturating_duration_since(w.opened) < self.window {
                w.held += 1;
                return None;
            }
            let held = w.held;
            *w = Window {
                opened: now,
                held: 0,
            };
            return Some(held);
        }
        if keys.len() >= MAX_KEYS {
            keys.clear();
        }
        let fresh = Window {
            opened: now,
            held: 0,
        };
        keys.insert(key.to_owned(), fresh);
        Some(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_logs_once_then_once_per_window_with_the_count() {
        let c = Collapse::new(Duration::from_secs(10));
        let t0 = Instant::now();
        assert_eq!(c.admit("503 bus-down", t0), Some(0));
        for i in 1..1000 {
            assert_eq!(c.admit("503 bus-down", t0 + Duration::from_millis(i)), None);
        }
        // Another key is not held back by the first.
        assert_eq!(c.admit("504 device-timeout", t0), Some(0));
        // The next window's first line reports the 999 held back.
        assert_eq!(
            c.admit("503 bus-down", t0 + Duration::from_secs(10)),
            Some(999)
        );
        assert_eq!(c.admit("503 bus-down", t0 + Duration::from_secs(11)), None);
        assert_eq!(c.held_note(0), "");
        assert_eq!(c.held_note(999), " (and 999 more like it in the last 10 s)");
    }

    #[test]
    fn many_distinct_keys_do_not_grow_without_bound() {
        let c = Collapse::new(Duration::from_secs(10));
        let t0 = Instant::now();
        for i in 0..10 * MAX_KEYS {
            assert_eq!(c.admit(&i.to_string(), t0), Some(0));
        }
        assert!(c.keys.lock().unwrap().len() <= MAX_KEYS);
    }
}
