//! How late a thread wakes from a timed sleep, learnt from its own sleeps,
//! so it can stop sleeping that much before an instant that matters (a
//! reply due at the bus owner, a byte due on the simulator's wire) and
//! spin only for the rest.
//!
//! A thread woken by a timer (on a VM, a halted virtual CPU woken by the
//! hypervisor) runs tens of µs after the time it asked for. A fixed lead
//! either wakes too late on such a host (the line idles after each reply
//! until the owner notices it) or spins too long on a quiet one (CPU). The
//! estimate tracks a high quantile of the lateness seen: it rises quickly
//! after a late wake and decays slowly, so one lucky wake does not make the
//! next ones late.

use std::time::{Duration, Instant};

use super::skewed::Skewed;

/// The least lead: a wake on time still needs a moment to look at the line.
pub(crate) const MIN_LEAD: Duration = Duration::from_micros(10);
/// The most lead (and the largest sample taken): a wake later than this was
/// preemption, not timer lateness, and spinning through it would cost more
/// CPU than the idle line it saves.
pub(crate) const MAX_LEAD: Duration = Duration::from_micros(200);

/// Weight of a sample above the estimate (rises fast).
const RISE: f64 = 0.25;
/// Weight of a sample below the estimate (decays slowly). With these two
/// the estimate settles where about RISE/(RISE+DECAY) ≈ 93 % of the
/// samples are below it.
const DECAY: f64 = 0.02;

#[derive(Debug, Clone)]
pub(crate) struct WakeLateness {
    estimate: Skewed,
}

impl Default for WakeLateness {
    fn default() -> Self {
        Self {
            estimate: Skewed::new(MIN_LEAD, RISE, DECAY),
        }
    }
}

impl WakeLateness {
    /// How long before an instant the thread should stop sleeping.
    pub(crate) fn lead(&self) -> Duration {
        self.estimate.get().clamp(MIN_LEAD, MAX_LEAD)
    }

    /// When to stop sleeping to be awake by `due`.
    pub(crate) fn wake_at(&self, due: Instant) -> Instant {
        due.checked_sub(self.lead()).unwrap_or(due)
    }

    /// A sleep that asked to end at `asked` ended at `woke`.
    pub(crate) fn observe(&mut self, asked: Instant, woke: Instant) {
        let late = woke.saturating_duration_since(asked).min(MAX_LEAD);
        self.estimate.feed(late);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(w: &mut WakeLateness, late_us: &[u64]) {
        let t0 = Instant::now();
        for l in late_us {
            w.observe(t0, t0 + Duration::from_micros(*l));
        }
    }

    #[test]
    fn starts_at_the_least_lead() {
        assert_eq!(WakeLateness::default().lead(), MIN_LEAD);
    }

    #[test]
    fn settles_near_a_high_quantile_of_the_lateness() {
        let mut w = WakeLateness::default();
        // 90 % of wakes 20 µs late, 10 % 60 µs late, interleaved.
        let pattern: Vec<u64> = (0..2000)
            .map(|i| if i % 10 == 0 { 60 } else { 20 })
            .collect();
        feed(&mut w, &pattern);
        let lead = w.lead().as_micros();
        assert!((20..=60).contains(&lead), "lead {lead} µs");
        assert!(
            lead > 20,
            "the estimate sits above the common case: {lead} µs"
        );
    }

    #[test]
    fn rises_fast_and_decays_slowly() {
        let mut w = WakeLateness::default();
        feed(&mut w, &[100; 20]);
        let high = w.lead();
        assert!(high >= Duration::from_micros(95), "{high:?}");
        feed(&mut w, &[10; 5]);
        assert!(w.lead() > Duration::from_micros(85), "{:?}", w.lead());
        feed(&mut w, &[10; 500]);
        assert!(w.lead() < Duration::from_micros(15), "{:?}", w.lead());
    }

    #[test]
    fn a_preempted_sleep_counts_as_the_most_lead_only() {
        let mut w = WakeLateness::default();
        feed(&mut w, &[50_000; 50]);
        assert_eq!(w.lead(), MAX_LEAD);
    }
}
