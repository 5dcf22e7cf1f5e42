//! A USB adapter's two clocks as the simulator models them: its USB
//! (micro)frame boundaries, and when the chip hands the host the bytes it
//! received (at the frame after a full packet, or after its latency timer).

use std::time::{Duration, Instant};

use crate::transport::adapter::{AdapterModel, FTDI_PACKET_PAYLOAD};

/// The USB (micro)frame clock: boundaries at `origin + k·period`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct UsbClock {
    origin: Instant,
    period: Duration,
}

impl UsbClock {
    /// A clock whose boundaries sit at `phase` (taken modulo the period)
    /// after `start`.
    pub(crate) fn new(start: Instant, period: Duration, phase: Duration) -> Self {
        let phase_ns = phase.as_nanos() % period.as_nanos().max(1);
        Self {
            origin: start + Duration::from_nanos(u64::try_from(phase_ns).unwrap_or(0)),
            period,
        }
    }

    /// The first boundary strictly after `t`.
    pub(crate) fn next_after(&self, t: Instant) -> Instant {
        let p = self.period.as_nanos().max(1);
        if t < self.origin {
            return self.origin;
        }
        let since = t.duration_since(self.origin).as_nanos();
        let k = since / p + 1;
        self.origin + Duration::from_nanos(u64::try_from(k * p).unwrap_or(u64::MAX))
    }
}

/// When the chip hands received bytes to the host.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RxRule {
    timer: Option<Duration>,
}

impl RxRule {
    pub(crate) fn of(model: AdapterModel) -> Self {
        Self {
            timer: model.latency_timer(),
        }
    }

    /// The moment the chip sends the host the next packet of the bytes it
    /// holds, received at `times` (one instant a byte, in order): a full
    /// packet at the frame after its last byte came in, a shorter one when
    /// the timer has run from its first. `None` with nothing held.
    pub(crate) fn release(&self, clock: &UsbClock, times: &[Instant]) -> Option<Instant> {
        let first = *times.first()?;
        Some(match self.timer {
            Some(_) if times.len() >= FTDI_PACKET_PAYLOAD => {
                clock.next_after(times[FTDI_PACKET_PAYLOAD - 1])
            }
            Some(timer) => clock.next_after(first + timer),
            None => clock.next_after(*times.last()?),
        })
    }

    /// How many of `held` bytes one packet takes: an FTDI chip sends at
    /// most 62 (a 64-byte packet less its two status bytes) and keeps the
    /// rest; the others are taken as sending all.
    pub(crate) fn packet(&self, held: usize) -> usize {
        match self.timer {
            Some(_) => held.min(FTDI_PACKET_PAYLOAD),
            None => held,
        }
    }
}
