//! Setpoints on the wire and the e-stop, against the simulator.

mod support;

use std::time::{Duration, Instant};

use jointd::bus::{BusError, Setpoint, Targets};
use jointd::protocol::{Command, Control, ControlOp, Frame, Group, InfoBlock};
use jointd::sim::{Fault, WireFrame};
use support::bus::*;

fn command(f: &WireFrame) -> Option<Command> {
    Frame::decode(&f.bytes)
        .ok()
        .and_then(|fr| Command::from_frame(&fr).ok())
}

#[tokio::test]
async fn broadcasts_coalesce_and_fill_other_slots_with_target_or_measured_angle() {
    let rig = rig_in_memory(&[1, 2, 3, 4, 5, 6, 7, 8]);
    rig.online(8).await;
    rig.enable_all(8).await;
    // Joint 3 to 20°, joint 4 to -10°: one control frame each (new speed limit).
    rig.bus
        .set_targets(&[(3, target(20.0)), (4, target(-10.0))]);
    rig.reaches(3, 20.0).await;
    rig.reaches(4, -10.0).await;
    // Joint 3 disabled and enabled again: no target of ours, it holds at 20°.
    rig.bus.disable(Targets::Ids(vec![3])).await.unwrap();
    rig.bus.enable(Targets::Ids(vec![3])).await.unwrap();

    // Joints 1 and 2 move: their first frames set the speed limit, the next share a broadcast.
    rig.bus.set_targets(&[(1, target(5.0)), (2, target(6.0))]);
    rig.reaches(1, 5.0).await;
    let mark = Instant::now();
    rig.bus.set_targets(&[(1, target(7.0)), (2, target(8.0))]);
    rig.reaches(2, 8.0).await;

    let cmds: Vec<Command> = rig
        .host_frames_since(mark)
        .iter()
        .filter_map(command)
        .collect();
    let bcasts: Vec<_> = cmds
        .iter()
        .filter_map(|c| match c {
            Command::BroadcastPos(b) => Some(*b),
            _ => None,
        })
        .collect();
    assert_eq!(bcasts.len(), 1, "one broadcast for both joints: {cmds:?}");
    let b = bcasts[0];
    assert_eq!(b.group, Group::Low);
    assert_eq!(&b.pos_ref[..2], &[7 * 128, 8 * 128]);
    // Slot 3: never commanded since its enable: its measured angle, not 0.
    assert!(
        (i32::from(b.pos_ref[2]) - 20 * 128).abs() < 128,
        "slot 3 = {}",
        b.pos_ref[2]
    );
    // Slot 4: its current target.
    assert_eq!(b.pos_ref[3], -10 * 128);
    assert!(!cmds.iter().any(|c| matches!(
        c,
        Command::Control(Control {
            op: ControlOp::SetRef,
            ..
        })
    )));
    // The device behind slot 3 kept its place.
    let d3 = rig.sim.device(3).unwrap();
    assert!(
        (d3.target_deg - 20.0).abs() < 1.0,
        "device 3 target {}",
        d3.target_deg
    );

    // A single changed joint gets a control frame, not a broadcast.
    let mark = Instant::now();
    rig.bus.set_targets(&[(1, target(9.0))]);
    rig.reaches(1, 9.0).await;
    let cmds: Vec<Command> = rig
        .host_frames_since(mark)
        .iter()
        .filter_map(command)
        .collect();
    assert!(cmds.contains(&Command::Control(Control::set_ref(1, 9 * 128, SPEED))));
    assert!(!cmds.iter().any(|c| matches!(c, Command::BroadcastPos(_))));
    rig.assert_no_collisions();
}

#[tokio::test]
async fn wire_acks_follow_setpoints_onto_the_wire() {
    let rig = rig(&[1, 2]);
    rig.online(2).await;
    rig.enable_all(2).await;
    let mut acks = rig.bus.wire_acks();
    let seq = rig.bus.set_targets(&[(1, target(1.0)), (2, target(2.0))]);
    let waited = tokio::time::timeout(WAIT, acks.wait_for(|a| a.seq >= seq)).await;
    let ack = *waited.expect("ack in time").expect("ack channel open");
    assert!(ack.at.is_some());
}

#[tokio::test]
async fn estop_disables_everything_ahead_of_queued_requests() {
    let rig = rig_in_memory(&[1, 2, 3, 4]);
    rig.online(4).await;
    rig.enable_all(4).await;
    rig.bus.set_targets(&[(1, target(10.0)), (2, target(10.0))]);
    // A long scan of absent ids keeps the owner busy; three reads queue behind it.
    let scan = tokio::spawn({
        let bus = rig.bus.clone();
        async move { bus.scan(100, 159).await }
    });
    rig.sim_until("the scan on the wire", |sim| {
        sim.frame_log()
            .iter()
            .any(|f| f.from_host && f.dev_id >= Some(100))
    });
    let reads: Vec<_> = (1..=3)
        .map(|id| {
            let bus = rig.bus.clone();
            tokio::spawn(async move { bus.read_info(id, InfoBlock::Info03).await })
        })
        .collect();
    // Let the reads reach the queue before the e-stop.
    rig.until("three requests queued", |s| s.queue_depth >= 3)
        .await;

    let report = rig.bus.estop().await.expect("e-stop");
    assert_eq!(
        report.frames_sent, 6,
        "0xFF, each of the 4 devices, 0xFF again"
    );
    assert_eq!(report.preempted_requests, 3);
    assert!(matches!(scan.await.unwrap(), Err(BusError::Preempted)));
    for r in reads {
        assert!(matches!(r.await.unwrap(), Err(BusError::Preempted)));
    }
    rig.sim_until("every device disabled", |sim| {
        (1..=4).all(|id| sim.device(id).is_some_and(|d| !d.enabled))
    });
    assert_eq!(rig.bus.shared().setpoints.get(1), None, "setpoints cleared");
    let first_disable = rig.host_frames().iter().filter_map(command).find(|c| {
        matches!(
            c,
            Command::Control(Control {
                op: ControlOp::Disable,
                ..
            })
        )
    });
    assert_eq!(
        first_disable,
        Some(Command::Control(Control::disable(0xFF)))
    );
    let disables = || -> Vec<Command> {
        rig.host_frames()
            .iter()
            .filter_map(command)
            .filter(|c| {
                matches!(
                    c,
                    Command::Control(Control {
                        op: ControlOp::Disable,
                        ..
                    })
                )
            })
            .collect()
    };
    rig.sim_until("the whole disable sequence on the wire", |_| {
        disables().len() >= 6
    });
    let disables = disables();
    assert_eq!(
        disables.last(),
        Some(&Command::Control(Control::disable(0xFF))),
        "the sequence ends with a second disable-all"
    );
    rig.assert_no_collisions();
    // The bus carries on after an e-stop.
    tokio::time::timeout(
        Duration::from_secs(5),
        rig.bus.read_info(1, InfoBlock::Info01),
    )
    .await
    .expect("in time")
    .expect("reads work again");
}

fn disables_of(rig: &Rig, id: u8) -> usize {
    rig.host_frames()
        .iter()
        .filter_map(command)
        .filter(|c| {
            matches!(c, Command::Control(Control { dev_id, op: ControlOp::Disable, .. }) if *dev_id == id)
        })
        .count()
}

#[tokio::test]
async fn estop_reads_every_device_back_and_disables_again_one_that_missed_it() {
    let rig = rig_in_memory(&[1, 2, 3, 4]);
    rig.online(4).await;
    rig.enable_all(4).await;
    // Device 3 misses the e-stop's three disable frames (0xFF, its own, 0xFF).
    rig.sim.inject(Fault::MissControl {
        dev_id: 3,
        count: 3,
    });
    let report = rig.bus.estop().await.expect("e-stop");
    assert_eq!(report.disabled_again, vec![3], "{report:?}");
    assert_eq!(report.confirmed, vec![1, 2, 3, 4], "{report:?}");
    assert!(report.still_enabled.is_empty() && report.unconfirmed.is_empty());
    rig.sim_until("every device disabled", |sim| {
        (1..=4).all(|id| sim.device(id).is_some_and(|d| !d.enabled))
    });
    assert_eq!(
        disables_of(&rig, 3),
        2,
        "its own in the sequence, then again"
    );
    assert_eq!(disables_of(&rig, 2), 1);
    rig.assert_no_collisions();
}

#[tokio::test]
async fn a_device_deaf_to_every_disable_is_reported_still_enabled() {
    let rig = rig(&[1, 2, 3]);
    rig.online(3).await;
    rig.enable_all(3).await;
    rig.sim.inject(Fault::MissControl {
        dev_id: 2,
        count: u32::MAX,
    });
    let report = rig.bus.estop().await.expect("e-stop frames written");
    assert_eq!(report.still_enabled, vec![2], "{report:?}");
    assert_eq!(report.disabled_again, vec![2]);
    assert_eq!(report.confirmed, vec![1, 3]);
    // The report tells the truth: the simulated joint is still enabled.
    assert!(rig.sim.device(2).is_some_and(|d| d.enabled));
}

#[tokio::test]
async fn rezero_of_a_joint_in_full_swing_is_confirmed() {
    // At the factory 230400 baud, with joint 2's stream of setpoints
    // interleaved between the re-zero frame and the read-back (as the
    // owner does so a one-shot request never freezes the other joints), the
    // read-back comes ~3 frames (2.6 ms) later: time for joint 1 in full
    // swing to turn over 1°.
    let rig = rig_with(sim_config(&[1, 2], 230_400), |_| {});
    rig.online(2).await;
    rig.enable_all(2).await;
    // Full speed (50000 rpm rotor, ~527 °/s at the output) towards 200°.
    rig.bus.set_targets(&[(
        1,
        Setpoint {
            pos_ref: 200 * 128,
            spd_ref: i16::MAX,
        },
    )]);
    rig.until("joint 1 turning faster than 400 °/s", |s| {
        s.devices[&1]
            .info02
            .is_some_and(|(i, _)| i.speed > i16::MAX / 4 * 3)
    })
    .await;
    let stream = TargetStream::start(rig.bus.clone(), vec![2], Duration::from_millis(1));
    // Between the re-zero frame and the read-back the joint travels more
    // than the 0.5° a standing joint is allowed: still a confirmed re-zero.
    let rezeroed = rig.bus.rezero(1).await;
    drop(stream);
    rezeroed.expect("re-zero confirmed");
    let angle = rig.sim.device(1).unwrap().angle_deg;
    assert!(angle.abs() < 30.0, "re-zeroed mid-swing, now {angle}°");
}
