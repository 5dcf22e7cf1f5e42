//! Discovery against the simulator: power-up announcements and an active
//! scan each find every device, telemetry flows, nothing collides.

mod support;

use std::time::Duration;

use jointd::sim::Fault;
use support::bus::*;

fn sixteen() -> Vec<u8> {
    (1..=16).collect()
}

#[tokio::test]
async fn announcements_register_devices_powered_up_with_the_daemon() {
    let rig = rig(&sixteen());
    let snap = rig.online(16).await;
    assert_eq!(snap.devices.keys().copied().collect::<Vec<_>>(), sixteen());
    rig.assert_no_collisions();
}

#[tokio::test]
async fn scan_discovers_sixteen_devices_already_running_and_polls_them() {
    let rig = rig_on_memory_after_boot(sim_config(&sixteen(), BAUD), |cfg| {
        cfg.scan_last = 18;
        // Ids 17 and 18 are absent: each costs a full reply timeout.
        cfg.timing.reply_margin_us = 100_000;
    });
    let snap = rig.online(16).await;
    assert_eq!(snap.devices.keys().copied().collect::<Vec<_>>(), sixteen());
    // Polls begin once the scan is over; telemetry keeps coming for every device.
    let snap = rig
        .until("INFO_02 of every device", |s| {
            s.devices.values().all(|d| d.info02.is_some())
        })
        .await;
    // Every id of the range was asked: 1..=18 over the wire.
    let asked: std::collections::BTreeSet<u8> =
        rig.host_frames().iter().filter_map(|f| f.dev_id).collect();
    assert!(asked.is_superset(&(1..=18).collect()), "asked {asked:?}");
    assert!(snap.counters.polls > 16);
    rig.assert_no_collisions();
}

#[tokio::test]
async fn expected_ids_are_polled_and_missing_ones_stay_offline() {
    let rig = rig_with(sim_config(&[1, 2, 3], BAUD), |cfg| {
        cfg.ids = vec![1, 2, 3, 7];
        cfg.timing.reply_margin_us = 2_000;
    });
    let snap = rig
        .until("1..=3 online, 7 missed", |s| {
            s.devices.values().filter(|d| d.online).count() == 3
                && s.devices.get(&7).is_some_and(|d| d.missed_polls >= 2)
        })
        .await;
    assert!(!snap.devices[&7].online);
    // Nothing was scanned: only the expected ids were asked.
    assert!(rig
        .host_frames()
        .iter()
        .all(|f| matches!(f.dev_id, Some(1 | 2 | 3 | 7))));
}

#[tokio::test]
async fn a_pty_refusing_rs485_mode_is_a_note_and_the_bus_runs() {
    let rig = rig(&[1]);
    let snap = rig.online(1).await;
    assert!(
        snap.port_notes
            .iter()
            .any(|n| n.contains("RS-485") && n.contains("not supported")),
        "notes: {:?}",
        snap.port_notes
    );
    // `rs485 = false` leaves the port alone: nothing asked, nothing to tell.
    let rig = rig_with(sim_config(&[1], BAUD), |cfg| cfg.rs485 = false);
    let snap = rig.online(1).await;
    assert!(
        snap.port_notes.iter().all(|n| !n.contains("RS-485")),
        "notes: {:?}",
        snap.port_notes
    );
}

#[tokio::test]
async fn a_scan_counts_a_device_whose_reply_came_after_its_deadline() {
    // A probe waits 5.5 ms (0.5 ms modelled reply, 5 ms margin) before the
    // next one goes out.
    const MARGIN_US: u64 = 5_000;
    // The bus knows only id 5 (absent): device 1 announced itself before.
    // On the in-memory line each probe is dated when it was written, so a
    // held-back simulator cannot land one on the reply (see `rig_in_memory`).
    let rig = rig_on_memory_after_boot(sim_config(&[1], BAUD), |cfg| {
        cfg.ids = vec![5];
        cfg.timing.reply_margin_us = MARGIN_US;
    });
    // Device 1 now answers 8.4 ms late: past the deadline of the probe of 1
    // and in the middle of the quiet between the probes of 2 and 3, which
    // end 5.9 and 11.8 ms after it. Ids 4 to 32 give a loaded machine time
    // to deliver it before the scan ends; a busy 2-core host can hold the
    // simulator's thread for more than the few milliseconds a shorter scan
    // leaves.
    rig.sim
        .inject(Fault::ExtraTurnaround(Duration::from_micros(8_400)));
    let found = rig.bus.scan(1, 32).await.expect("scan");
    assert_eq!(found, vec![1]);
}
