//! Scheduler tests: control: coalescing, budget, prepared frames, acks.

use super::*;
use crate::bus::Source;

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
            Slot::Batch {
                control: frames, ..
            } => {
                control += frames.len() as u32;
                poll += 1;
            }
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
        match bus.next() {
            Slot::Control(frame) => bus.send_control(&frame),
            Slot::Batch { control, .. } => control.iter().for_each(|f| bus.send_control(f)),
            _ => {}
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
    let seq = bus.store.set(
        &[(
            1,
            Setpoint {
                pos_ref: 1,
                spd_ref: 100,
            },
        )],
        Source::Rest,
    );
    bus.store.set(
        &[(
            2,
            Setpoint {
                pos_ref: 2,
                spd_ref: 100,
            },
        )],
        Source::Rest,
    );
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
