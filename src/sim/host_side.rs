//! What the runner saw of the host's side of the line, apart from the wire
//! the engine referees: how late it handed each reply over against the
//! wire model (the referee's own precision), host writes it could not date
//! or that a write delay made miss their USB frame, and reply bytes the
//! host was not reading fast enough to take.

use std::collections::VecDeque;
use std::time::Instant;

use super::stats::SimStats;

/// Delivery-error samples kept for measurement.
const DELIVERY_SAMPLES: usize = 100_000;

#[derive(Debug, Default)]
pub(crate) struct HostSide {
    delivery_errors_ns: VecDeque<i64>,
    undated_reads: u64,
    slipped_writes: u64,
    overrun_bytes: u64,
}

impl HostSide {
    /// A reply due at the host at `due` was handed over at `written`.
    pub(crate) fn delivered(&mut self, due: Instant, written: Instant) {
        let err = if written >= due {
            i64::try_from((written - due).as_nanos()).unwrap_or(i64::MAX)
        } else {
            -i64::try_from((due - written).as_nanos()).unwrap_or(i64::MAX)
        };
        if self.delivery_errors_ns.len() == DELIVERY_SAMPLES {
            self.delivery_errors_ns.pop_front();
        }
        self.delivery_errors_ns.push_back(err);
    }

    /// The delivery errors kept, oldest first (ns; negative when early).
    pub(crate) fn delivery_errors_ns(&self) -> Vec<i64> {
        self.delivery_errors_ns.iter().copied().collect()
    }

    /// Host writes read after the line went unwatched ([`SimStats::host_reads_undated`]),
    /// and those a write delay made slip a frame.
    pub(crate) fn read(&mut self, undated: u64, slipped: u64) {
        self.undated_reads += undated;
        self.slipped_writes += slipped;
    }

    /// Reply bytes the host side did not take.
    pub(crate) fn overrun(&mut self, bytes: usize) {
        self.overrun_bytes += bytes as u64;
    }

    /// `stats` with this side's counters.
    pub(crate) fn fill(&self, stats: SimStats) -> SimStats {
        SimStats {
            host_reads_undated: self.undated_reads,
            host_writes_slipped: self.slipped_writes,
            host_overrun_bytes: self.overrun_bytes,
            ..stats
        }
    }
}
