//! Line occupancy: the union of busy intervals (frames on the wire plus the
//! device turnaround before each reply), summed up to any instant.
//!
//! Intervals may be added out of order and may lie in the future (a reply
//! scheduled but not yet sent); the meter counts only what lies before the
//! instant asked about, so two snapshots give the occupancy between them.

use std::time::{Duration, Instant};

/// Intervals that ended this long ago are folded into the running total.
/// Late additions that start before the fold point are clipped to it.
const FOLD_LAG: Duration = Duration::from_millis(50);

#[derive(Debug, Clone)]
pub(crate) struct BusyMeter {
    /// Busy time of everything before `horizon`.
    folded: Duration,
    horizon: Option<Instant>,
    /// Disjoint, sorted intervals at or after `horizon`.
    segs: Vec<(Instant, Instant)>,
}

impl BusyMeter {
    pub(crate) fn new() -> Self {
        Self {
            folded: Duration::ZERO,
            horizon: None,
            segs: Vec::new(),
        }
    }

    /// Marks `[start, end)` busy (merged with what overlaps it).
    pub(crate) fn add(&mut self, start: Instant, end: Instant) {
        let start = self.horizon.map_or(start, |h| start.max(h));
        if end <= start {
            return;
        }
        let (mut s, mut e) = (start, end);
        self.segs.retain(|&(a, b)| {
            let touches = a <= e && s <= b;
            if touches {
                s = s.min(a);
                e = e.max(b);
            }
            !touches
        });
        let at = self.segs.partition_point(|&(a, _)| a < s);
        self.segs.insert(at, (s, e));
    }

    /// Busy time from the first interval up to `at`.
    pub(crate) fn busy_until(&self, at: Instant) -> Duration {
        let open: Duration = self
            .segs
            .iter()
            .filter(|(s, _)| *s < at)
            .map(|&(s, e)| e.min(at) - s)
            .sum();
        self.folded + open
    }

    /// Folds intervals that ended well before `now` into the total.
    pub(crate) fn fold(&mut self, now: Instant) {
        let Some(cut) = now.checked_sub(FOLD_LAG) else {
            return;
        };
        let done = self.segs.partition_point(|&(_, e)| e <= cut);
        for (s, e) in self.segs.drain(..done) {
            self.folded += e - s;
            self.horizon = Some(e);
        }
    }
}

impl Default for BusyMeter {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn us(n: u64) -> Duration {
        Duration::from_micros(n)
    }

    #[test]
    fn overlapping_intervals_count_once() {
        let t0 = Instant::now();
        let mut m = BusyMeter::new();
        m.add(t0, t0 + us(400));
        m.add(t0 + us(300), t0 + us(900));
        m.add(t0 + us(2000), t0 + us(2400));
        assert_eq!(m.busy_until(t0 + us(10_000)), us(1300));
        assert_eq!(m.busy_until(t0 + us(500)), us(500));
        assert_eq!(m.busy_until(t0), Duration::ZERO);
    }

    #[test]
    fn folding_keeps_the_total() {
        let t0 = Instant::now();
        let mut m = BusyMeter::new();
        m.add(t0 + us(1000), t0 + us(1400));
        m.add(t0, t0 + us(400));
        m.fold(t0 + Duration::from_secs(1));
        assert_eq!(m.busy_until(t0 + Duration::from_secs(1)), us(800));
        // A late interval before the fold point is clipped, not double counted.
        m.add(t0 + us(1200), t0 + us(1600));
        assert_eq!(m.busy_until(t0 + Duration::from_secs(1)), us(1000));
    }
}
