//! An enable never resumes a target set before the joint stopped driving
//! (power cut, e-stop, disable, fault): the joint enables holding where it
//! stands until a new target arrives. Each test interrupts a joint moving
//! towards 100°, writes the old target again as a streaming client that has
//! not noticed yet would, enables, and watches the simulated joint stand
//! still for 300 ms.

mod support;

use std::time::{Duration, Instant};

use jointd::bus::handle::{BusEvent, DisabledReason};
use jointd::bus::{Setpoint, Targets};
use jointd::protocol::status::fsm;
use jointd::sim::Fault;
use support::bus::*;

/// ~3000 rpm rotor, ~32 °/s at the output: 100° takes about 3 s.
const SLOW: i16 = 1966;
/// How far a joint holding its place may drift, degrees.
const STILL_DEG: f64 = 0.5;
/// How long a held joint is watched.
const WATCH: Duration = Duration::from_millis(300);

fn toward_100() -> Setpoint {
    Setpoint {
        pos_ref: 100 * 128,
        spd_ref: SLOW,
    }
}

/// Joint 1 of a one-joint rig enabled and on its way to 100°, past 20°.
async fn moving_rig() -> Rig {
    let rig = rig_with(sim_config(&[1], BAUD), |c| c.ids = vec![1]);
    rig.online(1).await;
    rig.enable_all(1).await;
    rig.bus.set_targets(&[(1, toward_100())]);
    rig.sim_until("joint 1 past 20°", |sim| {
        sim.device(1).is_some_and(|d| d.angle_deg > 20.0)
    });
    rig
}

fn angle(rig: &Rig) -> f64 {
    rig.sim.device(1).expect("device 1").angle_deg
}

/// Waits until the released joint has coasted to rest.
fn at_rest(rig: &Rig) {
    rig.sim_until("joint 1 at rest", |sim| {
        sim.device(1)
            .is_some_and(|d| !d.enabled && d.velocity_deg_s.abs() < 0.1)
    });
}

/// Enables joint 1, waits until it runs, and asserts it stays where it
/// stood for [`WATCH`].
async fn enable_and_assert_still(rig: &Rig) {
    let before = angle(rig);
    rig.bus.enable(Targets::Ids(vec![1])).await.expect("enable");
    rig.sim_until("joint 1 running", |sim| {
        sim.device(1).is_some_and(|d| d.fsm == fsm::RUN)
    });
    let start = Instant::now();
    while start.elapsed() < WATCH {
        let now = angle(rig);
        assert!(
            (now - before).abs() < STILL_DEG,
            "joint 1 moved from {before:.2}° to {now:.2}° after the enable"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let d = rig.sim.device(1).unwrap();
    assert!(
        (d.target_deg - before).abs() < STILL_DEG,
        "the device holds {:.2}°, not where it stood ({before:.2}°)",
        d.target_deg
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_cut_mid_move_then_enable_does_not_move() {
    let rig = moving_rig().await;
    let mark = Instant::now();
    rig.sim.inject(Fault::PowerCycle { dev_id: 1 });
    rig.until("joint 1 seen ready again", |s| {
        s.devices[&1]
            .info01
            .is_some_and(|(i, at)| at > mark && i.fsm == fsm::READY)
    })
    .await;
    at_rest(&rig);
    rig.until("shown disabled by the reset", |s| {
        s.devices[&1].disabled_reason == Some(DisabledReason::Reset)
    })
    .await;
    rig.bus.set_targets(&[(1, toward_100())]);
    enable_and_assert_still(&rig).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_mid_move_then_enable_does_not_move() {
    let rig = moving_rig().await;
    rig.bus.estop().await.expect("e-stop");
    at_rest(&rig);
    rig.bus.set_targets(&[(1, toward_100())]);
    enable_and_assert_still(&rig).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_disable_mid_move_then_enable_does_not_move() {
    let rig = moving_rig().await;
    rig.bus
        .disable(Targets::Ids(vec![1]))
        .await
        .expect("disable");
    at_rest(&rig);
    rig.bus.set_targets(&[(1, toward_100())]);
    enable_and_assert_still(&rig).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_target_after_the_enable_still_moves_the_joint() {
    let rig = moving_rig().await;
    rig.bus
        .disable(Targets::Ids(vec![1]))
        .await
        .expect("disable");
    at_rest(&rig);
    let mut events = rig.bus.events();
    rig.bus.enable(Targets::Ids(vec![1])).await.expect("enable");
    rig.bus.set_targets(&[(1, target(30.0))]);
    rig.reaches(1, 30.0).await;
    // No event claims a reset: the daemon disabled it itself.
    while let Ok(ev) = events.try_recv() {
        assert!(!matches!(ev, BusEvent::DeviceReset { .. }), "{ev:?}");
    }
    let snap = rig.bus.snapshot();
    assert_eq!(
        (snap.devices[&1].resets, snap.devices[&1].disabled_reason),
        (0, None)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stall_fault_mid_move_then_disable_and_enable_does_not_move() {
    let mut cfg = sim_config(&[1], BAUD);
    cfg.stall_fault_after = Duration::from_millis(200);
    let rig = rig_with(cfg, |c| c.ids = vec![1]);
    rig.online(1).await;
    rig.enable_all(1).await;
    rig.sim.inject(Fault::Stall {
        dev_id: 1,
        at_deg: Some(25.0),
    });
    rig.bus.set_targets(&[(1, toward_100())]);
    rig.until("shown disabled by the fault", |s| {
        s.devices[&1].disabled_reason == Some(DisabledReason::Fault)
    })
    .await;
    assert_eq!(rig.bus.shared().setpoints.get(1), None, "target forgotten");
    rig.sim.inject(Fault::ClearAll);
    rig.bus.set_targets(&[(1, toward_100())]);
    rig.bus
        .disable(Targets::Ids(vec![1]))
        .await
        .expect("disable clears the fault");
    at_rest(&rig);
    rig.bus.set_targets(&[(1, toward_100())]);
    enable_and_assert_still(&rig).await;
}
