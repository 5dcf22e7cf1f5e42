//! Host writes that reach the adapter late: a busy host, a USB hub shared
//! with a camera, a VM. Each host write is held a random delay before the
//! adapter sees it; it then leaves at the USB frame after that, never
//! before a write made earlier (the path keeps order).
//!
//! The delay follows a distribution given by its quantiles
//! (`--write-delay-us P50,P99,MAX` or `P50,P99,P99.9,MAX`): linear from 0
//! to the median, geometric between the median, p99 and p99.9, linear from
//! p99.9 to the maximum. Without a p99.9 it is the geometric mean of p99
//! and the maximum. Measured on a pseudo-terminal between a host and an
//! adapter emulator on this kind of machine: p50 38 µs, p99 122 µs,
//! p99.9 0.73 ms.

use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

/// The quantiles of the delay a host write takes to reach the adapter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteDelay {
    pub p50: Duration,
    pub p99: Duration,
    pub p999: Duration,
    pub max: Duration,
}

/// The longest delay accepted: beyond a second it is an unplugged adapter.
const MAX_DELAY: Duration = Duration::from_secs(1);

impl WriteDelay {
    /// `P50,P99,MAX` or `P50,P99,P99.9,MAX` in µs, non-decreasing.
    pub fn parse(spec: &str) -> Result<Self, String> {
        let usage = "expected P50,P99,MAX or P50,P99,P99.9,MAX in µs, e.g. 38,150,750,1000";
        let values = spec
            .split(',')
            .map(|v| {
                v.trim()
                    .parse::<u64>()
                    .map(Duration::from_micros)
                    .map_err(|_| format!("`{v}` is not a whole number of µs; {usage}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let (p50, p99, p999, max) = match values[..] {
            [p50, p99, max] => (p50, p99, geometric_mean(p99, max), max),
            [p50, p99, p999, max] => (p50, p99, p999, max),
            _ => return Err(format!("{} values; {usage}", values.len())),
        };
        if !(p50 <= p99 && p99 <= p999 && p999 <= max) {
            return Err(format!("quantiles must not decrease; {usage}"));
        }
        if max > MAX_DELAY {
            return Err(format!(
                "a maximum above {} ms is an unplugged adapter, not a late write",
                MAX_DELAY.as_millis()
            ));
        }
        Ok(Self {
            p50,
            p99,
            p999,
            max,
        })
    }

    /// The delay at quantile `u` in `[0, 1]`.
    pub(crate) fn quantile(&self, u: f64) -> Duration {
        let u = u.clamp(0.0, 1.0);
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        let (a, b, t, geometric) = if u <= 0.5 {
            (0.0, us(self.p50), u / 0.5, false)
        } else if u <= 0.99 {
            (us(self.p50), us(self.p99), (u - 0.5) / 0.49, true)
        } else if u <= 0.999 {
            (us(self.p99), us(self.p999), (u - 0.99) / 0.009, true)
        } else {
            (us(self.p999), us(self.max), (u - 0.999) / 0.001, false)
        };
        let v = if geometric && a > 0.0 && b > 0.0 {
            a * (b / a).powf(t)
        } else {
            a + (b - a) * t
        };
        Duration::from_secs_f64(v.max(0.0) / 1e6)
    }
}

fn geometric_mean(a: Duration, b: Duration) -> Duration {
    Duration::from_secs_f64((a.as_secs_f64() * b.as_secs_f64()).sqrt())
}

impl fmt::Display for WriteDelay {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let us = |d: Duration| d.as_micros();
        write!(
            f,
            "{},{},{},{}",
            us(self.p50),
            us(self.p99),
            us(self.p999),
            us(self.max)
        )
    }
}

/// The delay in force, shared between the simulator's handles (which
/// switch it at run time) and its adapter line (which applies it).
#[derive(Debug, Clone, Default)]
pub(crate) struct WriteDelayCell(Arc<Mutex<Option<WriteDelay>>>);

impl WriteDelayCell {
    pub(crate) fn new(initial: Option<WriteDelay>) -> Self {
        Self(Arc::new(Mutex::new(initial)))
    }

    fn lock(&self) -> MutexGuard<'_, Option<WriteDelay>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn set(&self, delay: Option<WriteDelay>) {
        *self.lock() = delay;
    }

    pub(crate) fn get(&self) -> Option<WriteDelay> {
        *self.lock()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::Rng;

    fn us(n: u64) -> Duration {
        Duration::from_micros(n)
    }

    #[test]
    fn parses_three_or_four_quantiles() {
        let d = WriteDelay::parse("38,150,750,1000").unwrap();
        assert_eq!(
            (d.p50, d.p99, d.p999, d.max),
            (us(38), us(150), us(750), us(1000))
        );
        let d = WriteDelay::parse("40, 160, 1000").unwrap();
        assert_eq!(d.p999, us(400));
        for bad in [
            "",
            "1,2",
            "1,2,3,4,5",
            "3,2,1",
            "a,2,3",
            "1,2,2000000",
            "-1,2,3",
        ] {
            assert!(WriteDelay::parse(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn samples_follow_the_quantiles_given() {
        let d = WriteDelay::parse("38,150,750,1000").unwrap();
        let mut rng = Rng::new(7);
        let mut v: Vec<Duration> = (0..200_000).map(|_| d.quantile(rng.unit())).collect();
        v.sort_unstable();
        let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize];
        assert!(q(0.5) >= us(36) && q(0.5) <= us(40), "{:?}", q(0.5));
        assert!(q(0.99) >= us(140) && q(0.99) <= us(160), "{:?}", q(0.99));
        assert!(q(0.999) >= us(650) && q(0.999) <= us(850), "{:?}", q(0.999));
        assert!(q(1.0) <= us(1000));
        assert_eq!(d.quantile(1.0), us(1000));
        assert_eq!(d.quantile(0.0), Duration::ZERO);
    }
}
