//! The bus planning for a USB adapter, set in its config: the adapter and a
//! transaction's cost are shown, an FTDI timer above 1 ms is reported with
//! its cost and fix, and streaming setpoints while polling stays correct
//! (every joint online, no collision, no timeout) with control frames riding
//! in front of polls.

mod support;

use jointd::bus::AdapterSetting;
use jointd::bus::Setpoint;
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

/// The bus's port note about its adapter, which must name `model`.
fn adapter_note<'a>(snap: &'a jointd::bus::BusSnapshot, model: &str) -> &'a str {
    snap.port_notes
        .iter()
        .find(|n| n.starts_with(&format!("adapter {model}")))
        .expect("an adapter note")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bus_set_for_ftdi_at_16_ms_says_so_and_keeps_every_joint() {
    let ids: Vec<u8> = (1..=8).collect();
    // The simulator behind the same chip, on the in-memory line: the
    // pipeline writes polls blind, each taken to reach the wire within a USB
    // frame of its write, as a USB adapter's do. A pty (or a simulator
    // dating bytes when it reads them) may put a write on the wire
    // milliseconds late, a delay no USB adapter adds, and the referee then
    // counts collisions the daemon could not have caused.
    let mut sim_cfg = sim_config(&ids, BAUD);
    sim_cfg.adapter = AdapterModel::Ftdi { latency_ms: 16 };
    let rig = rig_on_memory(sim_cfg, |c| {
        c.ids = ids.clone();
        c.adapter = AdapterSetting::Fixed(AdapterModel::Ftdi { latency_ms: 16 });
    });
    let snap = rig.online(8).await;
    assert_eq!(snap.adapter, "ftdi:16");
    // Two frames at 500000 baud, turnaround, 16 ms timer, a USB frame each way.
    assert!(snap.transaction_us > 18_000, "{}", snap.transaction_us);
    let note = adapter_note(&snap, "ftdi:16");
    assert!(
        note.contains("at 1 ms it would take") && note.contains("latency_timer"),
        "{note}"
    );

    rig.enable_all(8).await;
    let before = rig.bus.snapshot().counters.clone();
    for k in 0..200 {
        let targets: Vec<(u8, Setpoint)> = ids
            .iter()
            .map(|&id| {
                let sp = Setpoint {
                    pos_ref: (k % 40) * 128,
                    spd_ref: 3000,
                };
                (id, sp)
            })
            .collect();
        rig.bus.set_targets(&targets);
        tokio::time::sleep(std::time::Duration::from_millis(2)).await;
    }
    let after = rig.bus.snapshot();
    assert!(
        after.devices.values().all(|d| d.online),
        "a joint went offline"
    );
    assert_eq!(after.counters.timeouts, before.timeouts);
    assert_eq!(rig.sim.stats().collisions, 0);
    // Control frames went out in front of polls, in the same write.
    assert!(after.counters.frames_tx_batched > before.frames_tx_batched);
}

/// An adapter set in the config on a tty with no USB device behind it (a
/// pty here) is planned for, and the note says what that risks.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_usb_adapter_set_on_a_tty_without_usb_is_said_to_risk_collisions() {
    let rig = rig_with(sim_config(&[1], BAUD), |c| {
        c.ids = vec![1];
        c.adapter = AdapterSetting::Fixed(AdapterModel::Ch340);
    });
    let snap = rig.online(1).await;
    assert_eq!(snap.adapter, "ch340");
    let note = adapter_note(&snap, "ch340");
    assert!(
        note.contains("No USB device is behind this tty") && note.contains("adapter = \"native\""),
        "{note}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_native_line_batches_only_a_control_frame_in_front_of_a_poll() {
    let rig = rig(&[1, 2]);
    let snap = rig.online(2).await;
    assert_eq!(snap.adapter, "native");
    rig.enable_all(2).await;
    let before = rig.bus.snapshot().counters.clone();
    // Targets faster than the control budget: it runs out, and the frame
    // after which it allows no other rides in front of the next poll.
    let bus = rig.bus.clone();
    tokio::task::spawn_blocking(move || {
        for k in 0..1500 {
            let sp = Setpoint {
                pos_ref: (k % 20) * 128,
                spd_ref: 3000,
            };
            bus.set_targets(&[(1, sp), (2, sp)]);
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    })
    .await
    .expect("the streaming thread");
    let after = rig.bus.snapshot();
    let batched = after.counters.frames_tx_batched - before.frames_tx_batched;
    let polls = after.counters.polls - before.polls;
    assert!(batched > 0, "no control frame rode with a poll");
    assert!(
        batched <= polls,
        "{batched} batched frames for {polls} polls"
    );
    assert!(after.devices.values().all(|d| d.online));
    assert_eq!(rig.sim.stats().collisions, 0);
}
