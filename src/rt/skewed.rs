//! An estimate that follows its samples faster one way than the other, so
//! it settles at a high or a low quantile of them without keeping any: how
//! late a thread wakes (rises fast, [`crate::rt::wake`]) and how late
//! replies come (falls fast, `bus::reply_lag`).

use std::time::Duration;

#[derive(Debug, Clone)]
pub(crate) struct Skewed {
    estimate_us: f64,
    /// Weight of a sample above the estimate.
    up: f64,
    /// Weight of a sample below it.
    down: f64,
}

impl Skewed {
    /// Starting at `start`, moving by `up` of the gap to a higher sample
    /// and `down` of the gap to a lower one.
    pub(crate) fn new(start: Duration, up: f64, down: f64) -> Self {
        Self {
            estimate_us: start.as_secs_f64() * 1e6,
            up,
            down,
        }
    }

    pub(crate) fn get(&self) -> Duration {
        Duration::from_secs_f64(self.estimate_us.max(0.0) / 1e6)
    }

    /// One sample, either way.
    pub(crate) fn feed(&mut self, sample: Duration) {
        let sample = sample.as_secs_f64() * 1e6;
        let weight = if sample > self.estimate_us {
            self.up
        } else {
            self.down
        };
        self.estimate_us += (sample - self.estimate_us) * weight;
    }

    /// A sample that bounds the truth from above: taken only if it is lower.
    pub(crate) fn feed_if_lower(&mut self, sample: Duration) {
        if sample.as_secs_f64() * 1e6 < self.estimate_us {
            self.feed(sample);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_by_its_weight_each_way() {
        let mut s = Skewed::new(Duration::from_micros(100), 0.5, 0.25);
        s.feed(Duration::from_micros(200));
        assert_eq!(s.get(), Duration::from_micros(150));
        s.feed(Duration::from_micros(50));
        assert_eq!(s.get(), Duration::from_micros(125));
        s.feed_if_lower(Duration::from_micros(1_000));
        assert_eq!(s.get(), Duration::from_micros(125));
    }
}
