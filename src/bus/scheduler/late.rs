//! Reads whose reply did not come in time (timed out, given up for an
//! e-stop, or a probe some firmware does not answer): each reply may still
//! come, late, behind an adapter that holds bytes or a device that was
//! slow, and must then be taken as the answer it is, not as a power-up
//! announcement. An e-stop gives up a read and then reads every device
//! back, so several can be outstanding at once: remembering only the last
//! made a late READY from before the e-stop look like a device that reset.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::bus::wire::Want;

/// How many outstanding reads are remembered: an e-stop's give-up plus its
/// read-back of a bus of devices that stopped answering.
const KEPT: usize = 16;

/// How long after its due time a reply is still taken as late: past the
/// longest latency timer a USB-serial adapter can be set to (255 ms on
/// FTDI chips). A power-up announcement of a device whose reads went
/// unanswered this recently is taken as a late reply; the owner still
/// sees a reset by the state dropping (a device it believed enabled).
const KEPT_FOR: Duration = Duration::from_millis(300);

/// A read whose reply may still come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Late {
    pub want: Want,
    /// When its reply was due.
    pub due: Instant,
    /// Its request was written before this (when it was given up, or
    /// written): what the reply shows is the device before then.
    pub asked_before: Instant,
}

/// The reads waiting for a late reply, oldest first.
#[derive(Debug, Default)]
pub(crate) struct LateReplies {
    waiting: VecDeque<Late>,
}

impl LateReplies {
    /// The reply to `want`, due at `due`, asked before `asked_before`, may
    /// still come.
    pub(crate) fn expect(&mut self, want: Want, due: Instant, asked_before: Instant) {
        if self.waiting.len() == KEPT {
            self.waiting.pop_front();
        }
        self.waiting.push_back(Late {
            want,
            due,
            asked_before,
        });
    }

    /// A reply of `dev_id`'s block `index` came at `at`: the read it
    /// answers if one is still waited for (the oldest such), `None` if
    /// nobody asked for it.
    pub(crate) fn take(&mut self, dev_id: u8, index: u8, at: Instant) -> Option<Late> {
        self.waiting
            .retain(|l| at.saturating_duration_since(l.due) <= KEPT_FOR);
        let found = self
            .waiting
            .iter()
            .position(|l| l.want.dev_id == dev_id && l.want.index == index)?;
        self.waiting.remove(found)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn want(dev_id: u8, index: u8) -> Want {
        Want { dev_id, index }
    }

    fn due(late: Option<Late>) -> Option<Instant> {
        late.map(|l| l.due)
    }

    #[test]
    fn every_outstanding_read_is_matched_not_only_the_last() {
        let t0 = Instant::now();
        let mut late = LateReplies::default();
        late.expect(want(1, 1), t0, t0);
        late.expect(
            want(2, 2),
            t0 + Duration::from_millis(1),
            t0 + Duration::from_millis(1),
        );
        let at = t0 + Duration::from_millis(5);
        assert_eq!(due(late.take(1, 1, at)), Some(t0));
        assert_eq!(due(late.take(1, 1, at)), None, "one reply per read");
        assert_eq!(
            due(late.take(2, 2, at)),
            Some(t0 + Duration::from_millis(1))
        );
    }

    #[test]
    fn another_block_or_device_is_no_answer() {
        let t0 = Instant::now();
        let mut late = LateReplies::default();
        late.expect(want(1, 1), t0, t0);
        assert_eq!(due(late.take(1, 2, t0)), None);
        assert_eq!(due(late.take(2, 1, t0)), None);
        assert_eq!(due(late.take(1, 1, t0)), Some(t0));
    }

    #[test]
    fn a_read_is_forgotten_past_the_longest_adapter_hold() {
        let t0 = Instant::now();
        let mut late = LateReplies::default();
        late.expect(want(1, 1), t0, t0);
        assert_eq!(
            due(late.take(1, 1, t0 + KEPT_FOR + Duration::from_millis(1))),
            None
        );
    }

    #[test]
    fn the_oldest_reads_make_way_for_new_ones() {
        let t0 = Instant::now();
        let mut late = LateReplies::default();
        for id in 0..=KEPT as u8 {
            late.expect(want(id, 1), t0, t0);
        }
        assert_eq!(due(late.take(0, 1, t0)), None, "the oldest went");
        assert_eq!(due(late.take(KEPT as u8, 1, t0)), Some(t0));
    }
}
