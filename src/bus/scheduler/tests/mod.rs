//! The scheduler alone: no thread, no port, a fake clock (instants the
//! tests advance by hand). Each test drives `next` and feeds back what a
//! perfect line would do: frames leave in 400 µs, replies come when due.

use std::time::{Duration, Instant};

use super::*;
use crate::bus::config::BusConfig;
use crate::bus::firmware::FirmwareSetting;
use crate::bus::setpoints::Setpoint;
use crate::bus::wire::Want;
use crate::protocol::status::fsm;
use crate::protocol::{Command, Info01, Info02, Reply, ReplyBody};

const FRAME: Duration = Duration::from_micros(400);

/// A scheduler over `ids` (expected), its store, and the instant its port opened.
struct Bus {
    s: Scheduler,
    store: SetpointStore,
    now: Instant,
    estop: u64,
    request: bool,
}

/// Firmware fixed by config: these tests are about polls and control, not
/// the one-off revision probe (its tests set `auto` themselves).
fn config(ids: &[u8]) -> BusConfig {
    let mut cfg = BusConfig::new("t", "/dev/null", 500_000);
    cfg.ids = ids.to_vec();
    cfg.firmware = FirmwareSetting::Fixed(crate::protocol::params::Revision::V2_0_1);
    cfg
}

fn info01(id: u8, state: u8) -> Reply {
    Reply::new(
        id,
        ReplyBody::Info01(Info01 {
            fsm: state,
            angle: 100,
            ..Info01::default()
        }),
    )
}

fn info02(id: u8) -> Reply {
    Reply::new(
        id,
        ReplyBody::Info02(Info02 {
            angle: 100,
            ..Info02::default()
        }),
    )
}

impl Bus {
    /// `ids` expected and `online` of them announced, port open, quiet spell over.
    fn new(ids: &[u8], online: &[u8]) -> Self {
        Self::with(config(ids), online)
    }

    fn with(cfg: BusConfig, online: &[u8]) -> Self {
        let t0 = Instant::now();
        let mut s = Scheduler::new(&cfg, t0);
        s.link_up(t0);
        // Heard ready, then enabled by the daemon: running, target known.
        for &id in online {
            s.unsolicited(&info01(id, fsm::READY), t0);
            s.unsolicited(&info01(id, fsm::RUN), t0);
        }
        s.drain_events().for_each(drop);
        let now = t0 + LISTEN_ON_OPEN;
        // Every id is enabled by the daemon as far as the authority knows
        // (setpoints to ids with no device test the planner's drops).
        let store = SetpointStore::default();
        for id in 0..=u8::MAX {
            let epoch = store.authority().grant(id).epoch;
            store.authority().arm(id, epoch);
        }
        Self {
            s,
            store,
            now,
            estop: 0,
            request: false,
        }
    }

    fn next(&mut self) -> Slot {
        let work = Work {
            estop_generation: self.estop,
            request_queued: self.request,
            setpoints: &self.store,
        };
        self.s.next(self.now, &work)
    }

    fn set(&self, ids: impl IntoIterator<Item = u8>, pos: i16) {
        let targets: Vec<(u8, Setpoint)> = ids
            .into_iter()
            .map(|id| {
                (
                    id,
                    Setpoint {
                        pos_ref: pos,
                        spd_ref: 100,
                    },
                )
            })
            .collect();
        self.store.set(&targets, crate::bus::Source::Rest);
    }

    /// Writes `frame` now; the clock moves to the line's next write time.
    fn send_control(&mut self, frame: &Planned) {
        let end = self.s.sent(self.now, 1);
        self.s.control_sent(frame, end);
        self.now = self.now.max(self.s.clock().write_at());
    }

    /// Writes a poll now; its reply (if `answer`) comes when due, else the
    /// read times out at its deadline.
    fn do_poll(&mut self, dev_id: u8, block: InfoBlock, answer: bool) {
        let end = self.s.sent(self.now, 1);
        let window = self.s.reply_window(end);
        if answer {
            let reply = match block {
                InfoBlock::Info01 => info01(dev_id, fsm::RUN),
                _ => info02(dev_id),
            };
            self.s.reply(&reply, window.due, window.due);
            self.now = window.due;
        } else {
            let want = Want {
                dev_id,
                index: block.index(),
            };
            self.s.timed_out(want, window.due, window.deadline);
            self.now = window.deadline;
        }
    }

    /// Runs `n` slots on a perfect line (every device in `silent` never
    /// answers); returns them.
    fn run(&mut self, n: usize, silent: &[u8]) -> Vec<Slot> {
        (0..n).map(|_| self.step(silent)).collect()
    }

    fn step(&mut self, silent: &[u8]) -> Slot {
        let slot = self.next();
        match &slot {
            Slot::Listen { until } => self.now = *until,
            Slot::Control(frame) => self.send_control(frame),
            Slot::Poll { dev_id, block } => self.do_poll(*dev_id, *block, !silent.contains(dev_id)),
            Slot::Batch {
                control,
                dev_id,
                block,
            } => {
                // One write: the frames back to back, the poll's reply after.
                let end = self.s.sent(self.now, control.len() as u32);
                let frame = self.s.clock().frame_time();
                for (i, c) in control.iter().enumerate() {
                    self.s
                        .control_sent(c, end - frame * (control.len() - i) as u32);
                }
                self.do_poll(*dev_id, *block, !silent.contains(dev_id));
            }
            _ => {}
        }
        slot
    }

    /// Runs until every pending setpoint is on the wire (polls answered).
    fn flush(&mut self) -> Vec<Planned> {
        let mut frames = Vec::new();
        for _ in 0..200 {
            if self.s.pending().is_empty() && self.store.latest_seq() == self.seen() {
                break;
            }
            match self.step(&[]) {
                Slot::Control(frame) => frames.push(frame),
                Slot::Batch { control, .. } => frames.extend(control),
                _ => {}
            }
        }
        frames
    }

    fn seen(&mut self) -> u64 {
        self.s.control.seen_seq()
    }
}

fn controls(slots: &[Slot]) -> Vec<&Planned> {
    slots
        .iter()
        .filter_map(|s| match s {
            Slot::Control(f) => Some(f),
            _ => None,
        })
        .collect()
}

fn polls(slots: &[Slot]) -> Vec<(u8, InfoBlock)> {
    slots
        .iter()
        .filter_map(|s| match s {
            Slot::Poll { dev_id, block } => Some((*dev_id, *block)),
            _ => None,
        })
        .collect()
}

mod adapter;
mod control;
mod firmware;
mod jobs;
mod polls;
mod port;
mod priority;
