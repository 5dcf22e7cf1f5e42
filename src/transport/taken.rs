//! What a USB-serial driver's output count would say of a simulated
//! adapter: the host's bytes written, less those the adapter model took by
//! now (at the USB frame each leaves in).
//!
//! On hardware the count is the driver's (`TIOCOUTQ`). A simulated adapter
//! has no driver: the in-memory line keeps a [`TakenCount`] between its
//! ends, and a simulator behind a pseudo-terminal (whose own count says 0
//! at once) hands one to the port it opens for the bus
//! (`SimHandle::pty_opener`, [`super::tty::TtyPort::counted_by`]). A pty
//! opened without one has none: its writes are blind.
//!
//! A driver's count falls when the USB transfer completes, whoever reads
//! the bytes on the far side and whenever. Where the adapter model can say
//! at the host's write which frame takes it (the in-memory line, which
//! knows each write's instant: [`TakeRule`]), the count decides it there,
//! not when the simulator's thread gets round to reading the bytes: a
//! thread held off its CPU for milliseconds must not look like an adapter
//! that stopped taking bytes.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

/// A simulated adapter's rule for the frame that takes host bytes
/// written at an instant (each call is one write, in the order made).
pub trait TakeRule: Send + Sync + std::fmt::Debug {
    fn release_of(&self, written: Instant) -> Instant;
}

/// The count of one line.
#[derive(Debug, Default)]
pub struct TakenCount {
    inner: Mutex<Counts>,
}

#[derive(Debug, Default)]
struct Counts {
    /// Host bytes written so far.
    written: u64,
    /// Bytes the adapter took so far, each report added.
    total: u64,
    /// Reports not yet due: (when, the total then).
    due: VecDeque<(Instant, u64)>,
    /// The total of the last report due.
    done: u64,
    /// The adapter model's rule, run at each host write ([`TakeRule`]).
    rule: Option<Arc<dyn TakeRule>>,
    /// Writes decided by the rule that the model has not read yet: (the
    /// frame that takes them, bytes).
    decided: VecDeque<(Instant, usize)>,
    /// A driver whose count never falls (a simulated fault): the total
    /// taken when it stuck; what was written since stays unsent.
    stuck_at: Option<u64>,
}

impl Counts {
    fn take(&mut self, at: Instant, bytes: usize) {
        self.total += bytes as u64;
        self.due.push_back((at, self.total));
    }
}

impl TakenCount {
    fn lock(&self) -> MutexGuard<'_, Counts> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The adapter model decides at each host write which frame takes it.
    pub fn follow(&self, rule: Arc<dyn TakeRule>) {
        self.lock().rule = Some(rule);
    }

    /// The host wrote `bytes` more (now): with a rule, taken at the frame
    /// it names.
    pub fn wrote(&self, bytes: usize) {
        let mut c = self.lock();
        c.written += bytes as u64;
        if let Some(rule) = c.rule.clone() {
            let at = rule.release_of(Instant::now());
            c.take(at, bytes);
            c.decided.push_back((at, bytes));
        }
    }

    /// The adapter takes `bytes` more of the host's at `at` (the USB frame
    /// they leave in, perhaps still to come). Reports come in the order of
    /// their frames.
    pub fn took(&self, at: Instant, bytes: usize) {
        self.lock().take(at, bytes);
    }

    /// The model reads `bytes` more of the host's: the frame the rule
    /// decided takes the first of them (`None` without a rule).
    pub fn decided(&self, bytes: usize) -> Option<Instant> {
        let mut c = self.lock();
        let (at, _) = *c.decided.front()?;
        let mut left = bytes;
        while left > 0 {
            let Some(front) = c.decided.front_mut() else {
                break;
            };
            let n = left.min(front.1);
            front.1 -= n;
            left -= n;
            if front.1 == 0 {
                c.decided.pop_front();
            }
        }
        Some(at)
    }

    /// Everything written is gone (an unplug dropped what was on its way).
    pub fn settle(&self) {
        let mut c = self.lock();
        c.due.clear();
        c.decided.clear();
        c.done = c.written;
        c.total = c.written;
        if c.stuck_at.is_some() {
            c.stuck_at = Some(c.written);
        }
    }

    /// A driver whose count never falls (`true`: a simulated fault), or
    /// one that counts again: from now on every byte written stays
    /// unsent, however the adapter takes it. The bytes still go out.
    pub fn set_stuck(&self, stuck: bool) {
        let mut c = self.lock();
        c.stuck_at = stuck.then_some(c.written);
    }

    /// The host bytes not taken by `now`.
    pub fn unsent(&self, now: Instant) -> usize {
        let mut c = self.lock();
        while let Some(&(_, total)) = c.due.front().filter(|(at, _)| *at <= now) {
            c.done = total;
            c.due.pop_front();
        }
        let done = c.stuck_at.unwrap_or(c.done);
        usize::try_from(c.written.saturating_sub(done)).unwrap_or(usize::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn bytes_are_unsent_until_their_frame_comes() {
        let c = TakenCount::default();
        let now = Instant::now();
        c.wrote(3);
        assert_eq!(c.unsent(now), 3);
        c.took(now + Duration::from_secs(3600), 3);
        assert_eq!(c.unsent(now), 3, "taken at a frame still to come");
        c.wrote(1);
        c.took(now, 1);
        // Reports are in the order of their frames: the later one due
        // first is not seen before the earlier.
        assert_eq!(c.unsent(now), 4);
        c.settle();
        assert_eq!(c.unsent(now), 0);
    }

    #[test]
    fn a_stuck_count_never_falls_and_counts_again_once_freed() {
        let c = TakenCount::default();
        let now = Instant::now();
        c.set_stuck(true);
        c.wrote(20);
        c.took(now, 20);
        assert_eq!(c.unsent(now + Duration::from_secs(1)), 20);
        c.wrote(20);
        assert_eq!(c.unsent(now + Duration::from_secs(1)), 40);
        c.set_stuck(false);
        assert_eq!(
            c.unsent(now + Duration::from_secs(1)),
            20,
            "the taken 20 count"
        );
    }
}
