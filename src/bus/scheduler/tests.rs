//! The scheduler alone: no thread, no port, a fake clock (instants the
//! tests advance by hand). Each test drives `next` and feeds back what a
//! perfect line would do: frames leave in 400 µs, replies come when due.

use std::time::{Duration, Instant};

use super::*;
use crate::bus::config::BusConfig;
use crate::bus::setpoints::Setpoint;
use crate::protocol::reply::fsm;
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

fn config(ids: &[u8]) -> BusConfig {
    let mut cfg = BusConfig::new("t", "/dev/null", 500_000);
    cfg.ids = ids.to_vec();
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
        for &id in online {
            s.unsolicited(&info01(id, fsm::RUN), t0);
        }
        s.drain_events().for_each(drop);
        let now = t0 + LISTEN_ON_OPEN;
        Self {
            s,
            store: SetpointStore::default(),
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
        self.store.set(&targets);
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
            if let Slot::Control(frame) = self.step(&[]) {
                frames.push(frame);
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

// --- the port: opening, quiet spell, loss, backoff -------------------------

#[test]
fn a_new_bus_opens_its_port_at_once() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    let store = SetpointStore::default();
    let work = Work {
        estop_generation: 0,
        request_queued: true,
        setpoints: &store,
    };
    assert_eq!(s.next(t0, &work), Slot::Reopen { at: t0 });
}

#[test]
fn a_freshly_opened_port_is_only_listened_to() {
    let mut bus = Bus::new(&[1], &[1]);
    let opened = bus.now - LISTEN_ON_OPEN;
    bus.now = opened + Duration::from_millis(5);
    bus.request = true;
    assert_eq!(
        bus.next(),
        Slot::Listen {
            until: opened + LISTEN_ON_OPEN
        }
    );
}

#[test]
fn reopen_backoff_doubles_up_to_its_cap() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    let waits: Vec<u64> = (0..8)
        .map(|_| s.open_failed(t0).as_millis() as u64)
        .collect();
    assert_eq!(waits, vec![20, 40, 80, 160, 320, 640, 1000, 1000]);
    let store = SetpointStore::default();
    let work = Work {
        estop_generation: 0,
        request_queued: false,
        setpoints: &store,
    };
    assert_eq!(
        s.next(t0, &work),
        Slot::Reopen {
            at: t0 + BACKOFF_MAX
        }
    );
}

#[test]
fn a_successful_open_resets_the_backoff() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    s.open_failed(t0);
    s.open_failed(t0);
    assert!(!s.link_up(t0), "first open is no reconnect");
    assert_eq!(s.link_lost(t0), BACKOFF_FIRST);
    assert_eq!(s.open_failed(t0), BACKOFF_FIRST);
    assert!(s.link_up(t0), "second open is a reconnect");
}

#[test]
fn a_lost_link_takes_every_device_offline_and_drops_pending() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    bus.set([1, 2], 500);
    bus.s.prepare(bus.now, &bus.store);
    assert!(!bus.s.pending().is_empty());
    let lost_at = bus.now;
    assert_eq!(bus.s.link_lost(lost_at), BACKOFF_FIRST);
    assert!(bus.s.registry().online_ids().is_empty());
    assert!(bus.s.pending().is_empty());
    assert_eq!(bus.s.drain_events().count(), 2, "two DeviceOffline events");
    assert_eq!(
        bus.next(),
        Slot::Reopen {
            at: lost_at + BACKOFF_FIRST
        }
    );
}

#[test]
fn setpoints_written_while_down_are_stale_when_it_comes_back() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.link_lost(bus.now);
    bus.set([1], 700);
    assert!(matches!(bus.next(), Slot::Reopen { .. }));
    bus.s.link_up(bus.now);
    bus.s.unsolicited(&info01(1, fsm::RUN), bus.now);
    bus.now += LISTEN_ON_OPEN;
    let slots = bus.run(20, &[]);
    assert!(controls(&slots).is_empty(), "{slots:?}");
}

// --- priorities: e-stop, requests, scan ------------------------------------

#[test]
fn estop_beats_a_queued_request_and_pending_setpoints() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    bus.request = true;
    bus.estop = 1;
    assert_eq!(bus.next(), Slot::EStop { generation: 1 });
    assert!(!bus.s.estop_pending(1), "served once");
    assert_eq!(bus.next(), Slot::Request);
}

#[test]
fn estop_waits_only_for_the_line_to_free() {
    let mut bus = Bus::new(&[1], &[1]);
    let end = bus.s.sent(bus.now, 1);
    bus.estop = 1;
    let write_at = bus.s.clock().write_at();
    assert_eq!(write_at, end - Duration::from_micros(300));
    assert_eq!(bus.next(), Slot::Listen { until: write_at });
    bus.now = write_at;
    assert_eq!(bus.next(), Slot::EStop { generation: 1 });
}

#[test]
fn estop_is_served_on_a_down_bus_too() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.link_lost(bus.now);
    bus.estop = 3;
    assert_eq!(bus.next(), Slot::EStop { generation: 3 });
    assert!(matches!(bus.next(), Slot::Reopen { .. }));
}

#[test]
fn a_queued_request_beats_setpoints_and_polls() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    bus.request = true;
    assert_eq!(bus.next(), Slot::Request);
}

#[test]
fn the_startup_scan_runs_until_done_after_requests() {
    let mut bus = Bus::with(config(&[]), &[]);
    assert_eq!(bus.next(), Slot::Scan);
    bus.request = true;
    assert_eq!(bus.next(), Slot::Request, "a request goes before the scan");
    bus.request = false;
    assert_eq!(bus.next(), Slot::Scan, "not done: asked again");
    bus.s.scan_done();
    assert!(matches!(bus.next(), Slot::Listen { .. }));
}

// --- control: coalescing, budget, prepared frames, acks ---------------------

#[test]
fn a_first_target_goes_in_its_own_frame() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    match bus.next() {
        Slot::Control(f) => {
            assert!(matches!(f.command, Command::Control(_)));
            assert_eq!(f.carries.len(), 1);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn eight_joints_share_one_broadcast() {
    let ids: Vec<u8> = (1..=8).collect();
    let mut bus = Bus::new(&ids, &ids);
    bus.set(ids.clone(), 500);
    bus.flush();
    bus.set(ids.clone(), 600);
    let frames = bus.flush();
    assert_eq!(frames.len(), 1, "{frames:?}");
    assert!(matches!(frames[0].command, Command::BroadcastPos(_)));
    assert_eq!(frames[0].carries.len(), 8);
}

#[test]
fn sixteen_joints_take_two_broadcasts() {
    let ids: Vec<u8> = (1..=16).collect();
    let mut bus = Bus::new(&ids, &ids);
    bus.set(ids.clone(), 500);
    bus.flush();
    bus.set(ids.clone(), 600);
    let frames = bus.flush();
    let broadcasts = frames
        .iter()
        .filter(|f| matches!(f.command, Command::BroadcastPos(_)))
        .count();
    assert_eq!((frames.len(), broadcasts), (2, 2), "{frames:?}");
}

#[test]
fn control_keeps_within_its_share_while_telemetry_wants_the_wire() {
    let ids: Vec<u8> = (1..=8).collect();
    let mut bus = Bus::new(&ids, &ids);
    let start = bus.now;
    let (mut control, mut poll) = (0u32, 0u32);
    for i in 0..4000 {
        bus.set(ids.clone(), (i % 100) as i16);
        match bus.step(&[]) {
            Slot::Control(_) => control += 1,
            Slot::Poll { .. } => poll += 1,
            _ => {}
        }
    }
    let elapsed = (bus.now - start).as_secs_f64();
    let share = f64::from(control) * FRAME.as_secs_f64() / elapsed;
    assert!((0.30..=0.36).contains(&share), "control share {share:.3}");
    assert!(poll > 1000, "telemetry still flows: {poll}");
}

#[test]
fn setpoints_fill_the_line_when_nothing_is_polled() {
    // Device 1 is expected but silent: once its retry is asked, there is
    // nobody to poll, and setpoints take every slot beyond their budget.
    let mut bus2 = Bus::new(&[1], &[]);
    let retry = bus2.next();
    assert!(
        matches!(retry, Slot::Poll { dev_id: 1, .. }),
        "offline id asked"
    );
    bus2.do_poll(1, InfoBlock::Info01, false);
    for i in 0..10 {
        bus2.set([1], i);
        let slot = bus2.step(&[1]);
        assert!(matches!(slot, Slot::Control(_)), "slot {i}: {slot:?}");
    }
}

#[test]
fn the_prepared_frame_goes_out_if_no_setpoint_came_since() {
    let ids: Vec<u8> = (1..=8).collect();
    let mut bus = Bus::new(&ids, &ids);
    bus.set(ids.clone(), 500);
    bus.flush();
    bus.now += Duration::from_millis(10); // the budget refills
    bus.set(ids.clone(), 600);
    bus.s.prepare(bus.now, &bus.store);
    let prepared = bus.s.control.peek_prepared().cloned();
    let Slot::Control(frame) = bus.next() else {
        panic!("control expected")
    };
    assert_eq!(Some(frame), prepared);
}

#[test]
fn a_prepared_frame_waits_for_the_budget() {
    let ids: Vec<u8> = (1..=8).collect();
    let mut bus = Bus::new(&ids, &ids);
    bus.set(ids.clone(), 500);
    bus.flush();
    for pos in 0..4 {
        bus.set(ids.clone(), 600 + pos);
        bus.s.prepare(bus.now, &bus.store);
        if let Slot::Control(frame) = bus.next() {
            bus.send_control(&frame);
        }
    }
    bus.set(ids.clone(), 700);
    bus.s.prepare(bus.now, &bus.store);
    assert!(
        bus.s.control.peek_prepared().is_none(),
        "budget spent: nothing prepared"
    );
    assert!(matches!(bus.next(), Slot::Poll { .. }));
}

#[test]
fn a_setpoint_after_preparing_replans_the_frame() {
    let ids: Vec<u8> = (1..=8).collect();
    let mut bus = Bus::new(&ids, &ids);
    bus.set(ids.clone(), 500);
    bus.flush();
    bus.now += Duration::from_millis(10); // the budget refills
    bus.set(ids.clone(), 600);
    bus.s.prepare(bus.now, &bus.store);
    bus.set(ids.clone(), 700);
    let Slot::Control(frame) = bus.next() else {
        panic!("control expected")
    };
    let Command::BroadcastPos(b) = frame.command else {
        panic!("{frame:?}")
    };
    assert_eq!(
        b.pos_ref, [700; 8],
        "the newest targets, not the prepared ones"
    );
}

#[test]
fn wire_acks_follow_the_frames() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    let seq = bus.store.set(&[(
        1,
        Setpoint {
            pos_ref: 1,
            spd_ref: 100,
        },
    )]);
    bus.store.set(&[(
        2,
        Setpoint {
            pos_ref: 2,
            spd_ref: 100,
        },
    )]);
    let Slot::Control(first) = bus.next() else {
        panic!("control expected")
    };
    bus.send_control(&first);
    assert_eq!(bus.s.take_ack().map(|a| a.seq), Some(seq));
    bus.flush();
    assert_eq!(bus.s.take_ack().map(|a| a.seq), Some(seq + 1));
}

#[test]
fn setpoints_for_unknown_ids_are_dropped_and_counted() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([40], 500);
    let slot = bus.next();
    assert!(!matches!(slot, Slot::Control(_)), "{slot:?}");
    assert_eq!(bus.s.take_dropped(), 1);
    assert!(bus.s.pending().is_empty());
}

#[test]
fn a_target_the_device_already_has_needs_no_frame() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    bus.flush();
    bus.set([1], 500);
    assert!(bus.flush().is_empty());
}

// --- polls: rotation, INFO_01 every Nth, offline back-off, timeouts ----------

#[test]
fn online_devices_are_polled_in_turn() {
    let mut bus = Bus::new(&[1, 2, 3], &[1, 2, 3]);
    let ids: Vec<u8> = polls(&bus.run(9, &[])).iter().map(|p| p.0).collect();
    assert_eq!(ids, vec![1, 2, 3, 1, 2, 3, 1, 2, 3]);
}

#[test]
fn every_eighth_poll_of_a_device_reads_info01() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    let got = polls(&bus.run(32, &[]));
    for id in [1, 2] {
        let info01 = got
            .iter()
            .filter(|p| p.0 == id && p.1 == InfoBlock::Info01)
            .count();
        assert_eq!(info01, 2, "device {id}: {got:?}");
    }
}

#[test]
fn an_offline_id_is_asked_only_now_and_then() {
    let mut bus = Bus::new(&[1, 2], &[1]);
    let first = bus.run(40, &[2]);
    let asked: Vec<_> = polls(&first).into_iter().filter(|p| p.0 == 2).collect();
    assert_eq!(asked, vec![(2, InfoBlock::Info01)], "once, then backed off");
    bus.now += Duration::from_millis(200);
    let later = polls(&bus.run(3, &[2]));
    assert!(later.contains(&(2, InfoBlock::Info01)), "{later:?}");
}

#[test]
fn missed_replies_take_a_device_offline_after_three() {
    let mut bus = Bus::new(&[1], &[1]);
    for n in 1..=3 {
        let Slot::Poll { dev_id, block } = bus.next() else {
            panic!("poll expected")
        };
        bus.do_poll(dev_id, block, false);
        let entry = bus.s.registry().get(1).map(|e| e.state.clone());
        assert_eq!(entry.as_ref().map(|s| s.missed_polls), Some(n));
        assert_eq!(entry.map(|s| s.online), Some(n < 3));
    }
    let events: Vec<_> = bus.s.drain_events().collect();
    assert!(
        matches!(
            events.as_slice(),
            [BusEvent::DeviceOffline { dev_id: 1, .. }]
        ),
        "{events:?}"
    );
}

#[test]
fn a_missed_reply_frees_the_line_at_its_deadline() {
    let mut bus = Bus::new(&[1], &[1]);
    let end = bus.s.sent(bus.now, 1);
    let window = bus.s.reply_window(end);
    assert_eq!(window.due, end + Duration::from_micros(500));
    assert_eq!(window.deadline, window.due + Duration::from_millis(5));
    let want = Want {
        dev_id: 1,
        index: 1,
    };
    bus.s.timed_out(want, window.due, window.deadline);
    assert_eq!(bus.s.clock().free_at(), window.deadline);
}

#[test]
fn a_late_reply_widens_the_reply_deadline() {
    let mut bus = Bus::new(&[1], &[1]);
    let end = bus.s.sent(bus.now, 1);
    let narrow = bus.s.reply_window(end);
    let want = Want {
        dev_id: 1,
        index: InfoBlock::Info02.index(),
    };
    bus.s.timed_out(want, narrow.due, narrow.deadline);
    let late = narrow.due + Duration::from_millis(6);
    bus.s.unsolicited(&info02(1), late);
    let wide = bus.s.reply_window(end);
    assert_eq!(wide.deadline - narrow.deadline, Duration::from_millis(12));
}

#[test]
fn an_announcement_is_no_late_reply() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    let end = bus.s.sent(bus.now, 1);
    let narrow = bus.s.reply_window(end);
    let want = Want {
        dev_id: 1,
        index: InfoBlock::Info02.index(),
    };
    bus.s.timed_out(want, narrow.due, narrow.deadline);
    bus.s.unsolicited(
        &info01(2, fsm::READY),
        narrow.due + Duration::from_millis(6),
    );
    assert_eq!(bus.s.reply_window(end), narrow);
}

#[test]
fn a_rebooted_device_loses_its_pending_setpoint() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    bus.set([1, 2], 500);
    bus.s.prepare(bus.now, &bus.store);
    let effect = bus.s.unsolicited(&info01(1, fsm::READY), bus.now);
    assert!(effect.rebooted);
    assert_eq!(bus.s.pending().keys().copied().collect::<Vec<_>>(), vec![2]);
    assert!(bus.s.control.peek_prepared().is_none());
}

#[test]
fn an_idle_bus_listens_a_tick() {
    let mut bus = Bus::new(&[], &[]);
    bus.s.scan_done();
    assert_eq!(
        bus.next(),
        Slot::Listen {
            until: bus.now + IDLE_TICK
        }
    );
}

// --- one-shot requests: interleaving, exclusive phase, preemption -----------

#[test]
fn setpoints_interleave_at_most_twice_between_job_frames() {
    let mut bus = Bus::new(&[1, 2, 3, 9], &[1, 2, 3, 9]);
    bus.s.job_start();
    assert_eq!(bus.s.interleave(bus.now, &bus.store, 0), None);
    bus.set([1, 2, 3, 9], 500);
    assert_eq!(
        bus.s.interleave(bus.now, &bus.store, 0),
        None,
        "not before the request's first frame"
    );
    bus.s.job_frame(0).ok();
    let mut between = 0;
    while let Some(frame) = bus.s.interleave(bus.now, &bus.store, 0) {
        bus.send_control(&frame);
        between += 1;
    }
    assert_eq!(between, MAX_INTERLEAVED);
    bus.s.job_frame(0).ok();
    assert!(
        bus.s.interleave(bus.now, &bus.store, 0).is_some(),
        "again after the next"
    );
}

#[test]
fn nothing_interleaves_in_the_exclusive_phase() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.job_start();
    bus.s.job_frame(0).ok();
    bus.set([1], 500);
    bus.s.set_exclusive(true);
    assert_eq!(bus.s.interleave(bus.now, &bus.store, 0), None);
    bus.s.set_exclusive(false);
    assert!(bus.s.interleave(bus.now, &bus.store, 0).is_some());
}

#[test]
fn an_estop_preempts_a_job_except_in_its_exclusive_phase() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.job_start();
    assert_eq!(bus.s.job_frame(0), Ok(()));
    bus.set([1], 500);
    assert_eq!(
        bus.s.interleave(bus.now, &bus.store, 1),
        None,
        "no setpoint before an e-stop"
    );
    bus.s.set_exclusive(true);
    assert_eq!(
        bus.s.job_frame(1),
        Ok(()),
        "the baud switch runs to its end"
    );
    bus.s.set_exclusive(false);
    assert_eq!(bus.s.job_frame(1), Err(Preempted));
}
