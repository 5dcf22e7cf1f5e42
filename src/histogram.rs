//! A latency histogram in Prometheus' shape (cumulative buckets, sum,
//! count), cheap enough to observe on the bus owner's hot path: a fixed
//! array, no allocation, no lock of its own.

use std::time::Duration;

/// Bucket bounds, seconds: 0.1 ms (a frame at 500000 baud is 0.4 ms) to
/// 100 ms (an FTDI latency timer left at 16 ms is well inside).
pub const LATENCY_BUCKETS_S: [f64; 12] = [
    0.0001, 0.00025, 0.0005, 0.00075, 0.001, 0.0015, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1,
];

/// Observations of one latency since start.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Histogram {
    /// Per bucket of [`LATENCY_BUCKETS_S`] (not cumulative); beyond the last
    /// bound an observation counts only in `count`.
    in_bucket: [u64; LATENCY_BUCKETS_S.len()],
    sum_s: f64,
    count: u64,
}

impl Histogram {
    pub fn observe(&mut self, latency: Duration) {
        let s = latency.as_secs_f64();
        if let Some(i) = LATENCY_BUCKETS_S.iter().position(|le| s <= *le) {
            self.in_bucket[i] += 1;
        }
        self.sum_s += s;
        self.count += 1;
    }

    /// `(upper bound in seconds, observations at or below it)`, as the
    /// exposition format's `le` buckets want them (the `+Inf` one is `count`).
    pub fn cumulative(&self) -> impl Iterator<Item = (f64, u64)> + '_ {
        LATENCY_BUCKETS_S
            .iter()
            .zip(self.in_bucket.iter().scan(0u64, |acc, n| {
                *acc += n;
                Some(*acc)
            }))
            .map(|(le, n)| (*le, n))
    }

    pub fn sum_seconds(&self) -> f64 {
        self.sum_s
    }

    pub fn count(&self) -> u64 {
        self.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_cumulative_and_the_tail_counts_only_in_count() {
        let mut h = Histogram::default();
        for us in [50, 300, 300, 2_000, 500_000] {
            h.observe(Duration::from_micros(us));
        }
        let c: Vec<(f64, u64)> = h.cumulative().collect();
        assert_eq!(c[0], (0.0001, 1));
        assert_eq!(c[2], (0.0005, 3));
        assert_eq!(c[6], (0.0025, 4));
        assert_eq!(c.last().copied(), Some((0.1, 4)));
        assert_eq!(h.count(), 5);
        assert!((h.sum_seconds() - 0.50265).abs() < 1e-9);
    }
}
