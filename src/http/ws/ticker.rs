//! When a subscription's telemetry is sent: on a grid of its period that
//! the connections share, in a few lanes.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;
use std::time::Duration;

use tokio::time::{interval_at, Interval, MissedTickBehavior};

use super::telemetry::Subscription;

/// A subscription's clock: its first tick at once, the next ones on a grid
/// of its period shared by the connections (multiples of the period since
/// [`epoch`], in one of [`LANES`] phases). Clients at the same rate then
/// wake together in a few timer slots per period rather than each at its
/// own phase (a wake-up of the runtime's threads per client per tick). The
/// lanes keep one burst from holding a setpoint batch that arrives during
/// it behind every client's write.
pub(super) struct Ticker {
    first: bool,
    interval: Interval,
}

impl Ticker {
    /// A ticker at the subscription's rate; an idle one when unsubscribed.
    pub(super) fn new(sub: Option<&Subscription>) -> Self {
        let period = sub.map_or(Duration::from_secs(3600), |s| {
            Duration::from_secs_f64(1.0 / s.rate_hz)
        });
        static NEXT_LANE: AtomicU64 = AtomicU64::new(0);
        let lane = NEXT_LANE.fetch_add(1, Ordering::Relaxed) % LANES;
        let start = on_grid(tokio::time::Instant::now(), period, lane);
        let mut interval = interval_at(start, period);
        interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
        Self {
            first: sub.is_some(),
            interval,
        }
    }

    pub(super) async fn tick(&mut self) {
        if std::mem::take(&mut self.first) {
            return;
        }
        self.interval.tick().await;
    }
}

/// Phases of the grid that connections are dealt to in turn.
const LANES: u64 = 4;

/// The process's origin of the tick grid.
fn epoch() -> tokio::time::Instant {
    static EPOCH: OnceLock<tokio::time::Instant> = OnceLock::new();
    *EPOCH.get_or_init(tokio::time::Instant::now)
}

/// The first multiple of `period` since [`epoch`], shifted by `lane` / [`LANES`]
/// of a period, at or after `now` (`now` itself if the clock reads
/// earlier than that, as a test's paused clock may).
fn on_grid(now: tokio::time::Instant, period: Duration, lane: u64) -> tokio::time::Instant {
    let epoch = epoch() + period.mul_f64(lane as f64 / LANES as f64);
    let (Some(since), Ok(step)) = (
        now.checked_duration_since(epoch),
        u64::try_from(period.as_nanos()),
    ) else {
        return now;
    };
    if step == 0 {
        return now;
    }
    let since = u64::try_from(since.as_nanos()).unwrap_or(u64::MAX);
    let ticks = since.div_ceil(step);
    epoch + Duration::from_nanos(ticks.saturating_mul(step))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clients_at_one_rate_tick_on_one_grid() {
        let period = Duration::from_millis(10);
        let e = epoch();
        let ms = |n| e + Duration::from_millis(n);
        // Subscribed at different moments of one period: the same next tick.
        assert_eq!(on_grid(ms(21), period, 0), ms(30));
        assert_eq!(on_grid(ms(29), period, 0), ms(30));
        assert_eq!(on_grid(ms(30), period, 0), ms(30));
        // A rate that does not divide a second still lands on its multiples.
        let third = Duration::from_nanos(3_333_333);
        assert_eq!(on_grid(ms(5), third, 0), e + third * 2);
        // Another lane: the same grid a quarter period later.
        assert_eq!(
            on_grid(ms(21), period, 1),
            ms(22) + Duration::from_micros(500)
        );
        assert_eq!(
            on_grid(ms(23), period, 1),
            ms(32) + Duration::from_micros(500)
        );
    }

    #[test]
    fn a_clock_before_the_epoch_ticks_from_now() {
        let e = epoch();
        let Some(before) = e.checked_sub(Duration::from_millis(5)) else {
            return;
        };
        assert_eq!(on_grid(before, Duration::from_millis(10), 0), before);
    }
}
