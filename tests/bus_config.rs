//! Config writes verified by read-back or RES, a failed verification
//! reported, and an id change and a baud change end to end.

mod support;

use jointd::bus::handle::BusEvent;
use jointd::bus::BusError;
use jointd::protocol::params::index;
use jointd::protocol::{ConfigParam, Info04, InfoBlock};
use jointd::sim::Fault;
use support::bus::*;

#[tokio::test]
async fn writes_are_verified_by_read_back_and_res() {
    let rig = rig_in_memory(&[1, 2]);
    rig.online(2).await;
    let out = rig
        .bus
        .write_config(1, ConfigParam::PosLpf(3))
        .await
        .unwrap();
    assert_eq!(
        (out.index, out.value, out.verified_by),
        (16, 3, "read_back")
    );
    assert_eq!(rig.sim.device(1).unwrap().params.raw(index::POS_LPF_LV), 3);

    // A RES failure is the device saying no: the wrong flash key.
    let refused = rig
        .bus
        .write_config(1, ConfigParam::WriteFlash { key: 0 })
        .await;
    assert!(
        matches!(
            refused,
            Err(BusError::Refused {
                dev_id: 1,
                code: 0,
                ..
            })
        ),
        "{refused:?}"
    );
    let out = rig.bus.write_flash(1).await.unwrap();
    assert_eq!(out.verified_by, "res");
    assert_eq!(rig.sim.device(1).unwrap().flash.raw(index::POS_LPF_LV), 3);

    let silent = rig.bus.write_config(1, ConfigParam::CommSilent(1)).await;
    assert!(matches!(silent, Err(BusError::Invalid(_))));
    let unknown = rig.bus.write_config(99, ConfigParam::PosLpf(1)).await;
    assert!(matches!(
        unknown,
        Err(BusError::UnknownDevice { dev_id: 99, .. })
    ));
    rig.assert_no_collisions();
}

#[tokio::test]
async fn a_write_that_did_not_take_effect_is_a_verification_error() {
    // Replies given up on after 20 ms (not the rig's 500): lost read-backs
    // are retried here, and each costs a timeout.
    let rig = rig_with(sim_config(&[1], BAUD), |c| {
        c.timing.reply_margin_us = 20_000
    });
    rig.online(1).await;
    // Garbled bytes on the line: a corrupted write is not applied, while the
    // read-back after it may come through and show the old value. Every
    // send is read back (and re-sent) as often as the bus allows first.
    rig.sim.inject(Fault::CorruptRate(0.03));
    let mut mismatch = None;
    for i in 0..300u16 {
        let value = 4000 + i;
        match rig.bus.write_config(1, ConfigParam::MaxCur(value)).await {
            Ok(out) => assert_eq!(
                rig.sim.device(1).unwrap().params.raw(index::MAX_CUR),
                out.value
            ),
            Err(BusError::VerifyMismatch {
                expected, found, ..
            }) => {
                assert_eq!(expected, value);
                assert_eq!(rig.sim.device(1).unwrap().params.raw(index::MAX_CUR), found);
                mismatch = Some(found);
                break;
            }
            Err(BusError::Unverified { value: v, .. }) => assert_eq!(v, value),
            Err(e) => panic!("unexpected {e}"),
        }
    }
    assert!(mismatch.is_some(), "no write was lost in 300 tries");
    rig.sim.inject(Fault::ClearAll);
}

#[tokio::test]
async fn id_change_moves_the_device_and_its_registry_entry() {
    let rig = rig_in_memory(&[1, 2, 3]);
    rig.online(3).await;
    let mut events = rig.bus.events();
    let taken = rig.bus.set_id(3, 2).await;
    assert!(matches!(taken, Err(BusError::WrongState(_))), "{taken:?}");

    let out = rig.bus.set_id(3, 20).await.unwrap();
    assert_eq!((out.dev_id, out.verified_by), (20, "res"));
    event(&mut events, "id changed", |e| {
        matches!(
            e,
            BusEvent::IdChanged {
                old: 3,
                new: 20,
                ..
            }
        )
    })
    .await;
    assert!(rig.sim.device(20).is_some() && rig.sim.device(3).is_none());
    let changed_at = std::time::Instant::now();
    let snap = rig
        .until("telemetry from id 20", |s| {
            s.devices
                .get(&20)
                .and_then(|d| d.info02)
                .is_some_and(|(_, at)| at > changed_at)
        })
        .await;
    assert!(!snap.devices.contains_key(&3));
    assert_eq!(
        rig.bus
            .read_info(20, InfoBlock::Info01)
            .await
            .unwrap()
            .dev_id,
        20
    );
    rig.assert_no_collisions();
}

#[tokio::test]
async fn baud_change_switches_every_device_then_the_port() {
    let rig = rig_in_memory(&[1, 2]);
    rig.online(2).await;
    let mut events = rig.bus.events();
    rig.bus.set_baud(230_400).await.unwrap();
    event(&mut events, "baud changed", |e| {
        matches!(e, BusEvent::BaudChanged { baud: 230_400, .. })
    })
    .await;
    assert!(rig.sim.devices().iter().all(|d| d.baud == 230_400));
    let changed_at = std::time::Instant::now();
    let snap = rig
        .until("telemetry at the new baud", |s| {
            s.baud == 230_400
                && s.devices
                    .values()
                    .all(|d| d.online && d.info02.is_some_and(|(_, at)| at > changed_at))
        })
        .await;
    assert_eq!(snap.baud, 230_400);
    let info = rig.bus.read_info(1, InfoBlock::Info04).await.unwrap();
    assert_eq!(Info04::from_bytes(&info.data).baud_level, 1);
    // And back.
    rig.bus.set_baud(500_000).await.unwrap();
    assert!(rig.sim.devices().iter().all(|d| d.baud == 500_000));
    // Devices switch one at a time: the frame that switches device 2 reaches
    // the already switched device 1 at the wrong baud, once each way.
    assert_eq!(rig.sim.stats().baud_mismatches, 2);
    rig.assert_no_collisions();
}
