//! An e-stop racing an enable on rev 2.0.8 firmware (enable passes through
//! `start`, disable through `stop`, an enable during `stop` is ignored and
//! sent again once the device settles) is an e-stop: every joint ends
//! disabled for the e-stop, and no device is reported reset. Behind a
//! USB adapter that holds replies, a reply the e-stop gave up on comes
//! late, after the e-stop's own read-back: it answers a read, it is no
//! power-up announcement.
//!
//! Each round starts the enable and fires the e-stop at another point of
//! it, found by condition (the enable frame not yet out, a joint leaving
//! ready, a joint in `start`, a joint still in `stop` from the round
//! before), never by a fixed delay. `start` and `stop` last 10 ms, and the
//! test sees the simulator only by polling it: a poller woken late on a
//! busy host finds the joint past the state, so each wait also takes the
//! state after it. The e-stop then races the rest of the enable, and the
//! outcome asserted is the same at every point.

mod support;

use jointd::bus::handle::{BusEvent, DisabledReason};
use jointd::bus::{AdapterSetting, Targets};
use jointd::protocol::params::Revision;
use jointd::sim::Firmware;
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

const IDS: [u8; 4] = [1, 2, 3, 4];
/// The rev 2.0.8 states an enable and a disable pass through (SPEC §5's table).
const READY: u8 = 0;
const START: u8 = 6;
const RUN: u8 = 7;
const STOP: u8 = 8;

/// Where in the enable the e-stop is fired.
#[derive(Debug, Clone, Copy)]
enum RacePoint {
    /// At once: the enable may not have reached the wire.
    AtOnce,
    /// Once a simulated joint left ready.
    LeavingReady,
    /// Once a joint is in `start`.
    Starting,
    /// The enable sent while the joints are still in `stop` from a disable
    /// (the enable is ignored and sent again); the e-stop during the wait.
    WhileStopping,
}

const POINTS: [RacePoint; 4] = [
    RacePoint::AtOnce,
    RacePoint::LeavingReady,
    RacePoint::Starting,
    RacePoint::WhileStopping,
];

fn rev_2_0_8_rig(adapter: Option<AdapterModel>) -> Rig {
    let mut sim_cfg = sim_config(&IDS, BAUD);
    sim_cfg.firmware = Firmware::parse("2.0.8").expect("firmware");
    match adapter {
        Some(model) => {
            sim_cfg.adapter = model;
            rig_on_memory(sim_cfg, |c| {
                c.ids = IDS.to_vec();
                c.adapter = AdapterSetting::Fixed(model);
            })
        }
        // In memory: see `rig_in_memory`.
        None => rig_on_memory(sim_cfg, |c| c.ids = IDS.to_vec()),
    }
}

fn any_joint(rig: &Rig, pred: impl Fn(u8) -> bool) -> bool {
    IDS.iter()
        .any(|&id| rig.sim.device(id).is_some_and(|d| pred(d.fsm)))
}

async fn race(rig: &Rig, point: RacePoint) {
    if let RacePoint::WhileStopping = point {
        rig.enable_all(IDS.len()).await;
        // The disable confirms once the joints are ready again: the enable
        // must go while one is still in `stop`.
        let bus = rig.bus.clone();
        let disable = tokio::spawn(async move { bus.disable(Targets::All).await });
        rig.sim_until("a joint in stop (or past it)", |_| {
            any_joint(rig, |f| f == STOP || f == READY)
        });
        // Enabled while the disable confirms: either may finish first.
        let enable = enable_queued(rig).await;
        let report = rig.bus.estop().await.expect("e-stop");
        assert!(report.still_enabled.is_empty(), "{report:?}");
        let _ = disable.await.expect("disable task");
        let _ = enable.await.expect("enable task");
        return settled(rig);
    }
    let enable = enable_queued(rig).await;
    match point {
        RacePoint::AtOnce | RacePoint::WhileStopping => {}
        RacePoint::LeavingReady => {
            rig.sim_until("a joint leaving ready", |_| any_joint(rig, |f| f != READY));
        }
        RacePoint::Starting => {
            rig.sim_until("a joint in start (or past it)", |_| {
                any_joint(rig, |f| f == START || f == RUN)
            });
        }
    }
    let report = rig.bus.estop().await.expect("e-stop");
    assert!(report.still_enabled.is_empty(), "{report:?}");
    // The enable either finished before the e-stop or was cut short by it.
    let _ = enable.await.expect("enable task");
    settled(rig);
}

/// Asks for the enable and waits until the owner has it: an e-stop after
/// this races the enable; an enable asked after the e-stop would rightly
/// enable the joints.
async fn enable_queued(rig: &Rig) -> tokio::task::JoinHandle<Result<(), jointd::bus::BusError>> {
    let queued = rig.bus.snapshot().counters.requests_queued;
    let bus = rig.bus.clone();
    let enable = tokio::spawn(async move { bus.enable(Targets::All).await });
    rig.until("the enable queued", |s| s.counters.requests_queued > queued)
        .await;
    enable
}

fn settled(rig: &Rig) {
    rig.sim_until("every joint disabled and settled", |sim| {
        IDS.iter()
            .all(|&id| sim.device(id).is_some_and(|d| !d.enabled && d.fsm == READY))
    });
}

async fn rounds(rig: &Rig, n: usize) {
    let mut events = rig.bus.events();
    for round in 0..n {
        let point = POINTS[round % POINTS.len()];
        race(rig, point).await;
        // Once the e-stop's read-back and every late reply are in: the
        // owner has taken in a reply of each joint showing it ready.
        let seen = rig
            .until("the owner saw every joint ready", |s| {
                IDS.iter().all(|id| {
                    s.devices
                        .get(id)
                        .and_then(|d| d.info01)
                        .is_some_and(|(i, _)| i.fsm == READY)
                })
            })
            .await;
        for id in IDS {
            let d = &seen.devices[&id];
            assert_eq!(
                (d.resets, d.disabled_reason),
                (0, Some(DisabledReason::Estop)),
                "round {round} ({point:?}), device {id}: {:?}, {}",
                d.last_reset,
                summary(&seen)
            );
        }
        while let Ok(ev) = events.try_recv() {
            assert!(
                !matches!(ev, BusEvent::DeviceReset { .. }),
                "round {round} ({point:?}): {ev:?}"
            );
        }
    }
    assert!(
        IDS.iter()
            .all(|&id| rig.sim.device(id).map(|d| d.firmware) == Some(Revision::V2_0_8)),
        "the rig runs rev 2.0.8"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_racing_an_enable_on_rev_2_0_8_is_no_reset() {
    let rig = rev_2_0_8_rig(None);
    rig.online(IDS.len()).await;
    rounds(&rig, 12).await;
    rig.assert_no_collisions();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn behind_an_ftdi_adapter_a_late_reply_is_no_reset() {
    let rig = rev_2_0_8_rig(Some(AdapterModel::Ftdi { latency_ms: 16 }));
    rig.online(IDS.len()).await;
    rounds(&rig, 12).await;
    rig.assert_no_collisions();
}
