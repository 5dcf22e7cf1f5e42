//! Statistics of a bus: rates over a one-second window (frames by kind,
//! wire utilisation as the daemon sees it, timeouts, setpoint age) and the
//! periodic snapshot the API reads.

use std::time::{Duration, Instant};

use crate::bus::handle::{BusCounters, BusRates};
use crate::bus::state::BusLatency;

/// Length of the window rates are computed over.
const WINDOW: Duration = Duration::from_secs(1);
/// Setpoint ages kept per window (16 joints at ~500 updates/s fit easily).
const MAX_AGE_SAMPLES: usize = 50_000;

pub(crate) struct Stats {
    window_start: Instant,
    base: BusCounters,
    ages_us: Vec<u64>,
    rates: BusRates,
    latency: BusLatency,
    publish_every: Duration,
    next_publish: Instant,
}

impl Stats {
    pub(crate) fn new(publish_every: Duration, now: Instant) -> Self {
        Self {
            window_start: now,
            base: BusCounters::default(),
            ages_us: Vec::new(),
            rates: BusRates::default(),
            latency: BusLatency::default(),
            publish_every,
            next_publish: now,
        }
    }

    /// Age of a setpoint when the last byte of its frame is due on the wire.
    pub(crate) fn setpoint_age(&mut self, age: Duration) {
        self.latency.setpoint_to_wire.observe(age);
        if self.ages_us.len() < MAX_AGE_SAMPLES {
            self.ages_us.push(age.as_micros() as u64);
        }
    }

    /// The snapshot is more than one period late.
    pub(crate) fn overdue(&self, now: Instant) -> bool {
        now > self.next_publish + self.publish_every
    }

    /// The snapshot is due (or overdue).
    pub(crate) fn due(&self, now: Instant) -> bool {
        now >= self.next_publish
    }

    /// A snapshot went out at `now`: the next is due a period later.
    pub(crate) fn published(&mut self, now: Instant) {
        self.next_publish = now + self.publish_every;
    }

    pub(crate) fn rates(&self) -> &BusRates {
        &self.rates
    }

    /// A config/read frame handed to the port to its reply read back.
    pub(crate) fn round_trip(&mut self, latency: Duration) {
        self.latency.round_trip.observe(latency);
    }

    pub(crate) fn latency(&self) -> &BusLatency {
        &self.latency
    }

    /// The reply timeout as of the last window (shown with the rates).
    pub(crate) fn set_reply_timeout(&mut self, timeout: Duration) {
        self.rates.reply_timeout_us = timeout.as_micros() as u64;
    }

    pub(crate) fn set_wake_lead(&mut self, lead: Duration) {
        self.rates.wake_lead_us = lead.as_micros() as u64;
    }

    pub(crate) fn set_reply_lag(&mut self, lag: Duration) {
        self.rates.reply_lag_us = lag.as_micros() as u64;
    }

    /// Closes the window if it is over; returns its length when it did.
    pub(crate) fn roll(&mut self, now: Instant, counters: &BusCounters) -> Option<Duration> {
        let window = now.saturating_duration_since(self.window_start);
        if window < WINDOW {
            return None;
        }
        self.rates = rates(&self.base, counters, window, &mut self.ages_us);
        self.base = counters.clone();
        self.window_start = now;
        self.ages_us.clear();
        Some(window)
    }
}

fn rates(base: &BusCounters, now: &BusCounters, window: Duration, ages: &mut [u64]) -> BusRates {
    let secs = window.as_secs_f64();
    let per_s = |a: u64, b: u64| b.saturating_sub(a) as f64 / secs;
    let tx = |c: &BusCounters| {
        c.frames_tx_broadcast + c.frames_tx_control + c.frames_tx_config + c.frames_tx_jog
    };
    ages.sort_unstable();
    let pct = |p: f64| {
        let i = ((ages.len() as f64 * p).ceil() as usize).saturating_sub(1);
        ages.get(i).copied().unwrap_or(0)
    };
    BusRates {
        window_s: secs,
        frames_tx_per_s: per_s(tx(base), tx(now)),
        broadcast_per_s: per_s(base.frames_tx_broadcast, now.frames_tx_broadcast),
        control_per_s: per_s(base.frames_tx_control, now.frames_tx_control),
        config_per_s: per_s(base.frames_tx_config, now.frames_tx_config),
        frames_rx_per_s: per_s(base.frames_rx, now.frames_rx),
        polls_per_s: per_s(base.polls, now.polls),
        timeouts_per_s: per_s(base.timeouts, now.timeouts),
        wire_utilisation: per_s(base.wire_busy_us, now.wire_busy_us) / 1e6,
        setpoint_age_p50_us: pct(0.50),
        setpoint_age_p99_us: pct(0.99),
        setpoint_age_max_us: ages.last().copied().unwrap_or(0),
        reply_timeout_us: 0,
        wake_lead_us: 0,
        reply_lag_us: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_deltas_over_the_window() {
        let base = BusCounters {
            frames_tx_broadcast: 100,
            wire_busy_us: 1_000_000,
            ..BusCounters::default()
        };
        let now = BusCounters {
            frames_tx_broadcast: 1100,
            frames_tx_config: 500,
            polls: 500,
            wire_busy_us: 1_950_000,
            ..BusCounters::default()
        };
        let mut ages = vec![300, 100, 200, 5000];
        let r = rates(&base, &now, Duration::from_secs(1), &mut ages);
        assert_eq!(r.broadcast_per_s, 1000.0);
        assert_eq!(r.frames_tx_per_s, 1500.0);
        assert!((r.wire_utilisation - 0.95).abs() < 1e-9);
        assert_eq!(
            (
                r.setpoint_age_p50_us,
                r.setpoint_age_p99_us,
                r.setpoint_age_max_us
            ),
            (200, 5000, 5000)
        );
    }
}
