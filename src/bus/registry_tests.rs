use super::*;

#[test]
fn the_end_of_align_is_reported_once() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    let run = r.on_reply(&info01(1, fsm::RUN, 0), now, true, &mut ev);
    assert!(!run.now_running, "run without align before it");
    r.on_reply(&info01(2, fsm::ALIGN, 0), now, true, &mut ev);
    assert!(
        r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev)
            .now_running
    );
    assert!(
        !r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev)
            .now_running
    );
}

fn info01(id: u8, fsm: u8, err: u8) -> Reply {
    Reply::new(
        id,
        ReplyBody::Info01(Info01 {
            fsm,
            err_code: err,
            soft_ver: 128,
            temp_raw: 80,
            angle: 640,
            vbus: 1536,
        }),
    )
}

#[test]
fn announcement_registers_and_misses_take_a_device_offline() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.on_reply(&info01(4, 0, 0), now, false, &mut ev);
    assert!(r.is_online(4));
    assert!(matches!(ev[0], BusEvent::DeviceOnline { dev_id: 4, .. }));
    assert_eq!(r.slot_info(4).unwrap().measured, Some(640));
    for _ in 0..2 {
        r.on_missed(4, &mut ev);
    }
    assert!(r.is_online(4), "two misses are not enough");
    r.on_missed(4, &mut ev);
    assert!(!r.is_online(4));
    assert!(matches!(ev[1], BusEvent::DeviceOffline { dev_id: 4, .. }));
    r.on_reply(&info01(4, 0, 0), now, true, &mut ev);
    assert!(r.is_online(4), "comes back by itself");
}

#[test]
fn a_joint_the_daemon_enabled_before_its_first_status_is_not_found_enabled() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.expect(2);
    r.expect(3);
    r.note_enabled(2);
    let ours = r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev);
    assert!(!ours.found_enabled, "the daemon's own enable");
    let before_us = r.on_reply(&info01(3, fsm::RUN, 0), now, true, &mut ev);
    assert!(before_us.found_enabled, "enabled before the daemon started");
}

#[test]
fn a_second_announcement_is_a_reset_that_forgets_target_and_mode() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.on_reply(&info01(2, 0, 0), now, true, &mut ev);
    r.set_mode(2, CtrlMode::Speed);
    r.record_sent(
        2,
        Setpoint {
            pos_ref: 1,
            spd_ref: 2,
        },
        now,
    );
    let fx = r.on_reply(&info01(2, 0, 0), now, false, &mut ev);
    assert!(fx.reset);
    let s = &r.get(2).unwrap().state;
    assert_eq!((s.mode, s.target_sent), (None, None));
    assert_eq!(
        (s.resets, s.disabled_reason),
        (1, Some(DisabledReason::Reset))
    );
    assert!(matches!(
        ev.last(),
        Some(BusEvent::DeviceReset {
            dev_id: 2,
            seen: ResetSignal::Announcement,
            ..
        })
    ));
}

#[test]
fn a_dropped_state_is_a_reset_that_keeps_the_mode_the_daemon_set() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.expect(2);
    r.note_enabled(2);
    r.set_mode(2, CtrlMode::Speed);
    r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev);
    let fx = r.on_reply(&info01(2, fsm::READY, 0), now, true, &mut ev);
    assert!(fx.reset && !fx.powered_up, "{fx:?}");
    // Not known to be a power-up: the device may still run speed mode,
    // and a position target read as a speed would spin it.
    assert_eq!(r.get(2).unwrap().state.mode, Some(CtrlMode::Speed));
}

#[test]
fn replies_asked_before_a_disable_neither_confirm_it_nor_make_a_reset() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    r.expect(2);
    r.note_enabled(2);
    r.on_reply(&info01(2, fsm::ALIGN, 0), Instant::now(), true, &mut ev);
    let asked = Instant::now();
    r.note_disabled(2, DisabledReason::Estop);
    // Behind a USB adapter, polls written before the disable answer
    // after it: ready from before the enable took, then align.
    for state in [fsm::READY, fsm::ALIGN] {
        let fx = r.on_reply_asked(
            &info01(2, state, 0),
            Instant::now(),
            true,
            Some(asked),
            &mut ev,
        );
        assert!(!fx.reset, "{fx:?}");
    }
    let fx = r.on_reply(&info01(2, fsm::READY, 0), Instant::now(), true, &mut ev);
    assert!(!fx.reset, "the daemon's own disable, not a reset: {fx:?}");
    let s = &r.get(2).unwrap().state;
    assert_eq!(
        (s.resets, s.disabled_reason),
        (0, Some(DisabledReason::Estop))
    );
}

#[test]
fn a_status_from_before_the_daemons_disable_is_no_reason_for_a_reset() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.expect(2);
    r.note_enabled(2);
    r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev);
    r.note_disabled(2, DisabledReason::Estop);
    // A reply that left the device before the disable reached it ...
    r.on_reply(&info01(2, fsm::RUN, 0), now, true, &mut ev);
    // ... then the disable shows.
    let fx = r.on_reply(&info01(2, fsm::READY, 0), now, true, &mut ev);
    assert!(!fx.reset, "the daemon's own disable, not a reset");
    assert_eq!(
        r.get(2).unwrap().state.disabled_reason,
        Some(DisabledReason::Estop)
    );
}

#[test]
fn a_fault_is_reported_once_on_entry() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.on_reply(&info01(1, 7, 0), now, true, &mut ev);
    r.on_reply(&info01(1, 9, 8), now, true, &mut ev);
    r.on_reply(&info01(1, 9, 8), now, true, &mut ev);
    let faults: Vec<_> = ev
        .iter()
        .filter(|e| matches!(e, BusEvent::Fault { .. }))
        .collect();
    assert_eq!(faults.len(), 1);
    assert!(matches!(faults[0], BusEvent::Fault { name: "stall", .. }));
}

#[test]
fn rates_count_control_updates_and_telemetry_per_window() {
    let mut r = Registry::new("b", 3);
    let mut ev = Vec::new();
    let now = Instant::now();
    r.on_reply(&info01(1, 0, 0), now, true, &mut ev);
    let sp = Setpoint {
        pos_ref: 0,
        spd_ref: 0,
    };
    (0..4).for_each(|_| r.record_sent(1, sp, now));
    r.roll_rates(Duration::from_millis(500));
    let s = &r.get(1).unwrap().state;
    assert_eq!((s.control_hz, s.telemetry_hz), (8.0, 2.0));
}

#[test]
fn rename_moves_the_entry() {
    let mut r = Registry::new("b", 3);
    r.expect(3);
    r.rename(3, 12);
    assert!(r.get(3).is_none());
    assert_eq!(r.get(12).unwrap().state.dev_id, 12);
}
