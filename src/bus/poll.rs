//! How the wire is shared: a control budget (setpoints may take up to a
//! configured share of wire time while telemetry wants it) and the poll plan
//! that fills what is left (INFO_02 round-robin over online devices, INFO_01
//! every Nth poll of a device, offline devices asked now and then).
//!
//! Pure: driven by the instants and device lists the owner passes.

use std::time::{Duration, Instant};

use crate::protocol::InfoBlock;

/// How much wire time control frames may still take.
///
/// Credit grows with `share` × elapsed time and each control frame spends
/// its frame time. Capped at a few frames so an idle client cannot save up
/// a burst that starves telemetry.
#[derive(Debug, Clone)]
pub(crate) struct ControlBudget {
    share: f64,
    /// Wire time control may still use, seconds (negative: in debt).
    credit: f64,
    cap: f64,
    last: Instant,
}

/// How many frames of credit control may save up.
const CREDIT_CAP_FRAMES: f64 = 2.0;

impl ControlBudget {
    pub(crate) fn new(share: f64, frame: Duration, now: Instant) -> Self {
        let cap = CREDIT_CAP_FRAMES * frame.as_secs_f64();
        Self {
            share,
            credit: cap,
            cap,
            last: now,
        }
    }

    /// After a baud change the cap follows the frame time.
    pub(crate) fn set_frame(&mut self, frame: Duration) {
        self.cap = CREDIT_CAP_FRAMES * frame.as_secs_f64();
        self.credit = self.credit.min(self.cap);
    }

    /// The credit refilled up to `now`.
    fn credit_at(&self, now: Instant) -> f64 {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        (self.credit + self.share * dt).min(self.cap)
    }

    fn refill(&mut self, now: Instant) {
        self.credit = self.credit_at(now);
        self.last = self.last.max(now);
    }

    /// True when a control frame may go out now.
    pub(crate) fn allows(&mut self, now: Instant) -> bool {
        self.refill(now);
        self.credit >= 0.0
    }

    /// True when, after a control frame of `frame` time sent now, another
    /// would still be allowed once that one has left the line.
    pub(crate) fn allows_another(&self, now: Instant, frame: Duration) -> bool {
        // Spent now, refilled at the share while the frame is on the line.
        self.credit_at(now) - frame.as_secs_f64() * (1.0 - self.share) >= 0.0
    }

    /// Charges `wire` time of control frames.
    pub(crate) fn spend(&mut self, wire: Duration) {
        self.credit -= wire.as_secs_f64();
    }
}

/// What the poll plan remembers per device.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct PollState {
    /// Polls sent to this device (INFO_01 on every Nth).
    pub polls: u32,
    /// For an offline device: when to ask it again.
    pub retry_at: Option<Instant>,
}

/// An offline device's polls may take at most 1/this of the wire.
const OFFLINE_COST_INV: u32 = 20;

/// One telemetry read to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Poll {
    pub dev_id: u8,
    pub block: InfoBlock,
}

/// The round-robin cursor and the plan's parameters.
#[derive(Debug, Clone)]
pub(crate) struct PollPlanner {
    info01_every: u32,
    offline_interval: Duration,
    /// The id polled last; the next online id above it goes next.
    cursor: u8,
}

impl PollPlanner {
    pub(crate) fn new(info01_every: u32, offline_interval: Duration) -> Self {
        Self {
            info01_every: info01_every.max(1),
            offline_interval,
            cursor: 0,
        }
    }

    /// The next poll, given `(id, online, state)` of every known device in id
    /// order. An offline device whose retry is due goes first (INFO_01, the
    /// read that tells its state); else the next online device round-robin.
    /// Counts the poll in the device's state. `timeout` is what an
    /// unanswered poll costs: offline devices are asked no more often than
    /// keeps each one's cost within a small share of the wire.
    pub(crate) fn next<'a>(
        &mut self,
        devices: impl Iterator<Item = (u8, bool, &'a mut PollState)>,
        now: Instant,
        timeout: Duration,
    ) -> Option<Poll> {
        let offline_interval = self.offline_interval.max(timeout * OFFLINE_COST_INV);
        let mut online: Vec<(u8, &'a mut PollState)> = Vec::new();
        for (id, is_online, state) in devices {
            if is_online {
                online.push((id, state));
            } else if !matches!(state.retry_at, Some(t) if t > now) {
                state.retry_at = Some(now + offline_interval);
                return Some(Poll {
                    dev_id: id,
                    block: InfoBlock::Info01,
                });
            }
        }
        let pos = online
            .iter()
            .position(|(id, _)| *id > self.cursor)
            .unwrap_or(0);
        let (id, state) = online.into_iter().nth(pos)?;
        self.cursor = id;
        state.polls = state.polls.wrapping_add(1);
        let block = if state.polls % self.info01_every == 1 || self.info01_every == 1 {
            InfoBlock::Info01
        } else {
            InfoBlock::Info02
        };
        Some(Poll { dev_id: id, block })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRAME: Duration = Duration::from_micros(400);

    #[test]
    fn budget_limits_control_to_its_share_of_time() {
        let t0 = Instant::now();
        let mut b = ControlBudget::new(0.25, FRAME, t0);
        let mut sent = 0;
        // Offer a control slot every 100 µs for one second.
        for i in 0..10_000u32 {
            let now = t0 + Duration::from_micros(100 * u64::from(i));
            if b.allows(now) {
                b.spend(FRAME);
                sent += 1;
            }
        }
        // 0.25 s of wire / 400 µs = 625 frames, plus the initial credit.
        assert!((624..=628).contains(&sent), "sent {sent}");
    }

    #[test]
    fn idle_budget_saves_only_a_small_burst() {
        let t0 = Instant::now();
        let mut b = ControlBudget::new(0.5, FRAME, t0);
        let later = t0 + Duration::from_secs(10);
        let mut burst = 0;
        while b.allows(later) {
            b.spend(FRAME);
            burst += 1;
        }
        assert_eq!(burst, 3, "cap of two frames, the last spend goes into debt");
    }

    #[test]
    fn allows_another_foretells_the_next_decision() {
        let t0 = Instant::now();
        let mut b = ControlBudget::new(0.34, FRAME, t0);
        // Spend frame after frame, asking each time whether the next one
        // (a frame time later) will be allowed; the answer must match.
        let mut now = t0;
        for _ in 0..50 {
            if !b.allows(now) {
                now += FRAME;
                continue;
            }
            let foretold = b.allows_another(now, FRAME);
            b.spend(FRAME);
            now += FRAME;
            assert_eq!(b.allows(now), foretold, "at {:?}", now - t0);
        }
        // With a full credit of two frames, another is allowed after one.
        let fresh = ControlBudget::new(0.34, FRAME, t0);
        assert!(fresh.allows_another(t0, FRAME));
    }

    fn states(n: usize) -> Vec<PollState> {
        vec![PollState::default(); n]
    }

    #[test]
    fn polls_go_round_robin_with_info01_every_nth() {
        let t0 = Instant::now();
        let mut p = PollPlanner::new(3, Duration::from_millis(200));
        let mut st = states(3);
        let mut seen = Vec::new();
        for _ in 0..9 {
            let devs = st
                .iter_mut()
                .enumerate()
                .map(|(i, s)| (i as u8 + 1, true, s));
            let poll = p.next(devs, t0, FRAME).unwrap();
            seen.push((poll.dev_id, poll.block == InfoBlock::Info01));
        }
        let ids: Vec<u8> = seen.iter().map(|s| s.0).collect();
        assert_eq!(ids, vec![1, 2, 3, 1, 2, 3, 1, 2, 3]);
        let info01 = seen.iter().filter(|s| s.1).count();
        assert_eq!(info01, 3, "each device's first of every three polls");
    }

    #[test]
    fn offline_devices_are_asked_at_their_interval() {
        let t0 = Instant::now();
        let interval = Duration::from_millis(200);
        let mut p = PollPlanner::new(8, interval);
        let mut st = states(2);
        let mut poll_at = |st: &mut Vec<PollState>, now| {
            let devs = st
                .iter_mut()
                .enumerate()
                .map(|(i, s)| (i as u8 + 1, i == 0, s));
            p.next(devs, now, FRAME).unwrap()
        };
        assert_eq!(poll_at(&mut st, t0).dev_id, 2, "never asked: due now");
        assert_eq!(poll_at(&mut st, t0).dev_id, 1);
        assert_eq!(poll_at(&mut st, t0 + interval / 2).dev_id, 1);
        let due = poll_at(&mut st, t0 + interval);
        assert_eq!((due.dev_id, due.block), (2, InfoBlock::Info01));
    }

    #[test]
    fn a_long_timeout_spaces_offline_polls_out() {
        let t0 = Instant::now();
        let mut p = PollPlanner::new(8, Duration::from_millis(200));
        let mut st = states(1);
        let timeout = Duration::from_millis(25);
        let devs = st.iter_mut().map(|s| (1, false, s));
        assert!(p.next(devs, t0, timeout).is_some());
        assert_eq!(st[0].retry_at, Some(t0 + Duration::from_millis(500)));
    }

    #[test]
    fn nothing_to_poll_without_devices() {
        let mut p = PollPlanner::new(8, Duration::from_millis(200));
        assert_eq!(p.next(std::iter::empty(), Instant::now(), FRAME), None);
    }
}
