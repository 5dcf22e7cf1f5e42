//! Scheduler tests: polls: rotation, INFO_01 every Nth, offline back-off, timeouts.

use super::*;

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
fn a_late_ready_given_up_for_an_estop_is_no_reset_though_reads_timed_out_since() {
    // An e-stop gives up a read of device 1 (the device still ready, an
    // enable not yet taken), then its read-back of device 2 times out; the
    // late reply of device 1 answers the read, it is no announcement.
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    for id in [1, 2] {
        bus.s
            .registry_mut()
            .note_disabled(id, crate::bus::state::DisabledReason::Estop);
    }
    let end = bus.s.sent(bus.now, 1);
    let window = bus.s.reply_window(end);
    let info01_of = |dev_id| Want {
        dev_id,
        index: InfoBlock::Info01.index(),
    };
    bus.s.given_up(info01_of(1), window.due, window.due);
    bus.s.timed_out(info01_of(2), window.due, window.deadline);
    let effect = bus.s.unsolicited(
        &info01(1, fsm::READY),
        window.deadline + Duration::from_millis(2),
    );
    assert!(!effect.reset, "{effect:?}");
    assert!(
        !bus.s
            .drain_events()
            .any(|e| matches!(e, BusEvent::DeviceReset { .. })),
        "no reset reported"
    );
}

#[test]
fn a_reset_device_loses_its_pending_setpoint() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    bus.set([1, 2], 500);
    bus.s.prepare(bus.now, &bus.store);
    let effect = bus.s.unsolicited(&info01(1, fsm::READY), bus.now);
    assert!(effect.reset);
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

#[test]
fn a_running_device_polled_ready_is_a_reset_that_loses_its_pending_setpoint() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    bus.set([1, 2], 500);
    bus.s.prepare(bus.now, &bus.store);
    let due = bus.now + Duration::from_millis(1);
    let effect = bus.s.reply(&info01(1, fsm::READY), due, due);
    assert!(
        effect.reset,
        "announced running, now ready: the power-up went unheard"
    );
    assert_eq!(bus.s.pending().keys().copied().collect::<Vec<_>>(), vec![2]);
    assert!(bus.s.control.peek_prepared().is_none());
    let again = bus.s.reply(&info01(1, fsm::READY), due, due);
    assert!(!again.reset, "one detection per reset");
}

#[test]
fn a_late_reply_of_a_running_device_is_no_reset() {
    let mut bus = Bus::new(&[1], &[1]);
    let effect = bus.s.unsolicited(&info01(1, fsm::RUN), bus.now);
    assert!(!effect.reset);
}
