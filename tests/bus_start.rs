//! A joint found enabled when the daemon starts (left so by a daemon
//! stopped with `on_shutdown = "hold"`, or killed): `on_start = "disable"`
//! (the default) releases it first; `"keep"` leaves it enabled with its
//! target shown unknown, and touches it only when a client sends one.

mod support;

use std::time::Duration;

use jointd::bus::handle::{BusEvent, DisabledReason};
use jointd::bus::{Setpoint, ShutdownState, StartPolicy};
use jointd::protocol::status::fsm;
use support::bus::*;

/// A rig whose joints 1 and 2 are enabled, joint 1 still slowly moving
/// towards 100°, when its bus owner stops and a new one starts with `policy`.
async fn restarted_with(policy: Option<StartPolicy>) -> (Rig, BusEvent) {
    let ids = [1u8, 2];
    let mut rig = rig_with(sim_config(&ids, BAUD), |c| {
        c.ids = ids.to_vec();
        c.on_shutdown = ShutdownState::Hold;
    });
    rig.online(2).await;
    rig.enable_all(2).await;
    let slow = Setpoint {
        pos_ref: 100 * 128,
        spd_ref: 1966,
    };
    rig.bus.set_targets(&[(1, slow)]);
    rig.sim_until("joint 1 moving", |sim| {
        sim.device(1).is_some_and(|d| d.angle_deg > 5.0)
    });
    rig.restart_bus(|c| {
        if let Some(p) = policy {
            c.on_start = p;
        }
    });
    let mut events = rig.bus.events();
    let found = event(&mut events, "device 1 found enabled", |e| {
        matches!(e, BusEvent::FoundEnabled { dev_id: 1, .. })
    })
    .await;
    (rig, found)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn by_default_a_joint_found_enabled_is_disabled() {
    let (rig, found) = restarted_with(None).await;
    assert!(
        matches!(
            found,
            BusEvent::FoundEnabled {
                on_start: "disable",
                ..
            }
        ),
        "{found:?}"
    );
    rig.sim_until("both joints disabled", |sim| {
        [1, 2]
            .iter()
            .all(|id| sim.device(*id).is_some_and(|d| !d.enabled))
    });
    let snap = rig
        .until("shown disabled by on_start", |s| {
            s.devices.values().all(|d| {
                d.disabled_reason == Some(DisabledReason::OnStart)
                    && d.info01.is_some_and(|(i, _)| i.fsm == fsm::READY)
            })
        })
        .await;
    assert!(snap
        .devices
        .values()
        .all(|d| d.target_known && d.resets == 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keep_leaves_it_enabled_with_its_target_unknown() {
    let (rig, found) = restarted_with(Some(StartPolicy::Keep)).await;
    assert!(
        matches!(
            found,
            BusEvent::FoundEnabled {
                on_start: "keep",
                state: "run",
                ..
            }
        ),
        "{found:?}"
    );
    let snap = rig
        .until("both polled running", |s| {
            s.devices
                .values()
                .all(|d| d.info01.is_some_and(|(i, _)| i.fsm == fsm::RUN))
        })
        .await;
    for d in snap.devices.values() {
        assert!(!d.target_known, "device {} target shown known", d.dev_id);
        assert_eq!((d.target_sent, d.disabled_reason), (None, None));
    }
    // Joint 2 moving (one frame of its own) does not touch joint 1's target.
    rig.bus.set_targets(&[(2, target(10.0))]);
    rig.reaches(2, 10.0).await;
    let d1 = rig.sim.device(1).unwrap();
    assert!(d1.enabled && (d1.target_deg - 100.0).abs() < 0.01, "{d1:?}");
    let snap = rig
        .until("joint 2's target known", |s| s.devices[&2].target_known)
        .await;
    assert!(!snap.devices[&1].target_known);
    // Stays so: no release later either.
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert!(rig.sim.device(1).unwrap().enabled);
}
