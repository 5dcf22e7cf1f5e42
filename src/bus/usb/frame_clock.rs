//! The USB frame clock as the host infers it from reply arrivals: an
//! adapter hands received bytes to the host only at its USB (micro)frame
//! boundaries, so every read the bytes wake is a boundary plus the host's
//! own wake-up delay, never minus. [`FramePhase`] keeps the last arrivals and
//! takes as the boundary the earliest of the cluster they form, so a
//! stalled thread's late read does not move it. The estimate still runs
//! behind the adapter's clock by the least of those delays (tens of µs on
//! a busy host), which no arrival shows: the pipeline spares it before
//! each boundary ([`super::pipeline::UsbPipeline::set_arrival_lag`]).
//!
//! Pure: every instant is passed in.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Arrivals the phase estimate is made of.
pub(crate) const PHASE_SAMPLES: usize = 32;
/// The estimate is the start of the shortest stretch of the period that
/// holds this share of the arrivals (the rest are reads of a host that was
/// busy elsewhere when the bytes came).
const PHASE_QUANTILE: f64 = 0.8;
/// Arrivals needed before the estimate is trusted (before that, and
/// whenever the arrivals stop agreeing, every write is taken to leave as
/// late as it may: a period and the write's reach after it was made).
const PHASE_MIN_SAMPLES: usize = PHASE_SAMPLES;
/// The estimate is trusted once that share of the arrivals falls within
/// this part of a period after it (the host reads its replies promptly
/// enough for the boundaries to show), and until it no longer falls
/// within the wider one (hysteresis: a burst of late reads does not stop
/// the pipeline, which would then learn again from its slower polls).
const PHASE_TRUST_SPREAD: f64 = 0.25;
/// How far the trusted estimate may move per arrival (ns): well under the
/// guard for the few arrivals between two transfers, far above any drift.
const PHASE_SLEW_NS: i64 = 5_000;
const PHASE_DOUBT_SPREAD: f64 = 0.35;
/// ... but never below this (ns): on a 125 µs microframe a host's wake-up
/// jitter alone is a third of the period, and a write there is always held
/// for the later microframe anyway.
const DOUBT_FLOOR_NS: f64 = 60_000.0;
/// The USB frame clock as the host infers it from reply arrivals.
#[derive(Debug, Clone)]
pub(crate) struct FramePhase {
    period: Duration,
    /// A fixed reference (the first arrival); boundaries are
    /// `origin + offset + k·period`.
    origin: Option<Instant>,
    /// The last arrivals, as offsets from `origin` within a period (ns).
    samples: VecDeque<u64>,
    /// The estimated boundary offset (ns), once enough samples came and
    /// while they agree on it.
    offset: Option<u64>,
}

impl FramePhase {
    pub(crate) fn new(period: Duration) -> Self {
        Self {
            period,
            origin: None,
            samples: VecDeque::with_capacity(PHASE_SAMPLES),
            offset: None,
        }
    }

    /// The (micro)frame's length.
    pub(crate) fn period(&self) -> Duration {
        self.period
    }

    fn period_ns(&self) -> u64 {
        u64::try_from(self.period.as_nanos())
            .unwrap_or(u64::MAX)
            .max(1)
    }

    /// `t`'s offset within the period, from `origin` (`t` may be earlier).
    fn phase_of(&self, t: Instant) -> u64 {
        let p = self.period_ns();
        let origin = self.origin.unwrap_or(t);
        match t.checked_duration_since(origin) {
            Some(d) => (d.as_nanos() % u128::from(p)) as u64,
            None => {
                let back = (origin.duration_since(t).as_nanos() % u128::from(p)) as u64;
                (p - back) % p
            }
        }
    }

    /// A reply arrived at `at`: one more sample of "a boundary, a little earlier".
    pub(crate) fn arrival(&mut self, at: Instant) {
        self.origin.get_or_insert(at);
        if self.samples.len() == PHASE_SAMPLES {
            self.samples.pop_front();
        }
        self.samples.push_back(self.phase_of(at));
        if self.samples.len() >= PHASE_MIN_SAMPLES {
            let (offset, spread) = self.estimate();
            let limit = if self.offset.is_some() {
                PHASE_DOUBT_SPREAD
            } else {
                PHASE_TRUST_SPREAD
            };
            let limit_ns = (self.period_ns() as f64 * limit).max(if self.offset.is_some() {
                DOUBT_FLOOR_NS
            } else {
                0.0
            });
            let tight = (spread as f64) < limit_ns;
            self.offset = match (tight, self.offset) {
                (false, _) => None,
                (true, None) => Some(offset),
                (true, Some(old)) => Some(self.slew(old, offset)),
            };
        }
    }

    /// Moves the estimate from `old` toward `new` by at most [`PHASE_SLEW`]:
    /// the frame clock does not jump (a crystal drifts by well under a µs a
    /// ms), but a burst of late reads moves the raw estimate, and a jump
    /// between two transfers larger than the guard would put the second on
    /// the wire before the first's reply has ended.
    fn slew(&self, old: u64, new: u64) -> u64 {
        let p = self.period_ns() as i64;
        let mut d = (new as i64 - old as i64).rem_euclid(p);
        if d > p / 2 {
            d -= p;
        }
        let step = d.clamp(-PHASE_SLEW_NS, PHASE_SLEW_NS);
        (old as i64 + step).rem_euclid(p) as u64
    }

    /// The sample offset that starts the shortest stretch of the period
    /// holding [`PHASE_QUANTILE`] of the samples: the earliest arrivals of
    /// the cluster they form, since no arrival precedes its boundary.
    /// Returns it and the stretch's length (ns).
    fn estimate(&self) -> (u64, u64) {
        let p = self.period_ns();
        let n = self.samples.len();
        let k = ((n as f64 * PHASE_QUANTILE).ceil() as usize).clamp(1, n) - 1;
        let mut best = (u64::MAX, 0);
        let mut late: Vec<u64> = Vec::with_capacity(n);
        for &candidate in &self.samples {
            late.clear();
            late.extend(self.samples.iter().map(|&s| (s + p - candidate) % p));
            late.sort_unstable();
            if late[k] < best.0 {
                best = (late[k], candidate);
            }
        }
        (best.1, best.0)
    }

    /// True once the boundaries are known well enough to write blind.
    pub(crate) fn known(&self) -> bool {
        self.offset.is_some()
    }

    /// The first boundary strictly after `t` (by the estimate).
    pub(crate) fn boundary_after(&self, t: Instant) -> Instant {
        let p = self.period_ns();
        let offset = self.offset.unwrap_or(0);
        let into = (self.phase_of(t) + p - offset) % p;
        t + Duration::from_nanos(p - into)
    }

    /// The first boundary at or after `t`.
    pub(crate) fn boundary_at_or_after(&self, t: Instant) -> Instant {
        let p = self.period_ns();
        let offset = self.offset.unwrap_or(0);
        let into = (self.phase_of(t) + p - offset) % p;
        if into == 0 {
            t
        } else {
            t + Duration::from_nanos(p - into)
        }
    }

    pub(crate) fn forget(&mut self) {
        self.origin = None;
        self.samples.clear();
        self.offset = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn us(n: u64) -> Duration {
        Duration::from_micros(n)
    }

    #[test]
    fn boundaries_wrap_around_the_origin() {
        let t0 = Instant::now() + Duration::from_secs(1);
        let mut f = FramePhase::new(Duration::from_millis(1));
        // Arrivals straddling the period's end: 990 µs and 10 µs into it.
        for k in 1..=PHASE_SAMPLES as u64 {
            let late = if k % 2 == 0 { 990 } else { 1010 };
            f.arrival(t0 + us(1000 * k + late));
        }
        // The cluster starts at 990 µs (the 10 µs ones are 20 µs later).
        assert!(f.known());
        assert_eq!(f.boundary_after(t0 + us(5000)), t0 + us(5990));
        assert_eq!(f.boundary_at_or_after(t0 + us(5990)), t0 + us(5990));
        // Before the origin too.
        assert_eq!(f.boundary_after(t0 - us(500)), t0 - us(10));
    }
}
