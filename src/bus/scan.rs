//! Discovery by active scan: each id of a range is asked for INFO_01 once,
//! again only if the line carried garbage meanwhile (its reply may have
//! collided with a power-up announcement). A scan is a one-shot request
//! like the others, so setpoints interleave with it and an e-stop ends it.

use std::time::Instant;

use crate::protocol::command::index;
use crate::protocol::{is_device_id, Config, InfoBlock};

use super::error::BusError;
use super::link::Want;
use super::owner::Owner;

impl Owner {
    pub(super) fn scan(&mut self, first: u8, last: u8) -> Result<Vec<u8>, BusError> {
        if !is_device_id(first) || !is_device_id(last) || first > last {
            return Err(BusError::Invalid(format!(
                "scan range {first}..={last} must lie within 1..=159"
            )));
        }
        let started = Instant::now();
        let mut found = Vec::new();
        for id in first..=last {
            if self.probe(id)? {
                found.push(id);
            }
        }
        self.add_late_answers(first..=last, started, &mut found);
        Ok(found)
    }

    /// A reply that came after its deadline (a slow adapter, a loaded host)
    /// was taken in while later ids were probed: that device is there too.
    fn add_late_answers(
        &self,
        range: std::ops::RangeInclusive<u8>,
        since: Instant,
        found: &mut Vec<u8>,
    ) {
        let answered = |id: u8| {
            self.sched
                .registry()
                .get(id)
                .and_then(|e| e.state.info01)
                .is_some_and(|(_, at)| at >= since)
        };
        let late: Vec<u8> = range
            .filter(|id| !found.contains(id) && answered(*id))
            .collect();
        if late.is_empty() {
            return;
        }
        tracing::info!(bus = %self.cfg.name, "scan: {late:?} answered after their deadline");
        found.extend(late);
        found.sort_unstable();
    }

    /// Asks `id` for INFO_01 once; again (up to the configured retries) only
    /// if the line carried garbage meanwhile: silence means nobody is there,
    /// garbage may be its reply colliding with an announcement.
    fn probe(&mut self, id: u8) -> Result<bool, BusError> {
        let want = Want {
            dev_id: id,
            index: index::INFO_01_R,
        };
        for _ in 0..=self.cfg.timing.retries {
            let garbage = self.link.counters.skipped_bytes;
            if self
                .try_transact(Config::read(id, InfoBlock::Info01), want, 1)?
                .is_some()
            {
                return Ok(true);
            }
            if self.link.counters.skipped_bytes == garbage {
                return Ok(false);
            }
            self.link.counters.retries += 1;
        }
        Ok(false)
    }

    /// The scan of the configured range when no ids were given.
    pub(super) fn startup_scan(&mut self) {
        self.sched.job_start();
        let (first, last) = (self.cfg.scan_first, self.cfg.scan_last);
        match self.scan(first, last) {
            Ok(found) => {
                tracing::info!(bus = %self.cfg.name, ?found, "scan {first}..={last} done");
                self.sched.scan_done();
            }
            // Preempted or down: scan again once the bus runs.
            Err(e) => tracing::info!(bus = %self.cfg.name, "scan interrupted: {e}"),
        }
    }
}
