//! The simulator behind a USB adapter model, and the bus planning for the
//! same model: a reply waits in the chip as the model says; under every
//! model a 5 s stream of setpoints with polling loses no joint and collides
//! nowhere on the true wire.

mod support;

use std::time::{Duration, Instant};

use jointd::bus::{AdapterSetting, Setpoint};
use jointd::protocol::InfoBlock;
use jointd::sim::AdapterModel;
use support::bus::*;

#[test]
fn an_ftdi_chip_holds_a_reply_for_its_latency_timer() {
    let mut cfg = support::sim::config(&[1]);
    cfg.adapter = AdapterModel::Ftdi { latency_ms: 16 };
    let (_sim, mut host) = support::sim::memory(cfg);
    host.recv(support::sim::WAIT).expect("power-up INFO_01");
    let sent = Instant::now();
    host.read(1, InfoBlock::Info01).expect("a reply");
    // A lower bound only: the chip cannot give the reply back sooner than
    // its timer after the reply's first byte, which comes after the request.
    assert!(
        sent.elapsed() >= Duration::from_millis(16),
        "{:?}",
        sent.elapsed()
    );
}

#[test]
fn jointd_sim_refuses_a_bad_adapter_with_the_reason() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_jointd"))
        .args(["sim", "--ids", "1", "--adapter", "ftdi:0"])
        .output()
        .expect("run jointd sim");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("1..=255"), "{stderr}");
}

fn stream_for_5_s_behind(model: AdapterModel) {
    let ids: Vec<u8> = (1..=16).collect();
    let mut sim_cfg = sim_config(&ids, BAUD);
    sim_cfg.adapter = model;
    let rig = rig_on_memory(sim_cfg, |c| {
        c.ids = ids.clone();
        c.adapter = AdapterSetting::Fixed(model);
    });
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        rig.online(16).await;
        rig.enable_all(16).await;
        let start = rig.bus.snapshot().counters.clone();
        let until = Instant::now() + Duration::from_secs(5);
        let mut k = 0i16;
        while Instant::now() < until {
            let sp = Setpoint {
                pos_ref: (k % 40) * 128,
                spd_ref: 3000,
            };
            let targets: Vec<(u8, Setpoint)> = ids.iter().map(|&id| (id, sp)).collect();
            rig.bus.set_targets(&targets);
            k += 1;
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        let snap = rig.bus.snapshot();
        let offline: Vec<u8> = snap
            .devices
            .values()
            .filter(|d| !d.online)
            .map(|d| d.dev_id)
            .collect();
        assert!(offline.is_empty(), "{model}: offline {offline:?}");
        assert_eq!(rig.sim.stats().collisions, 0, "{model}: collisions");
        assert_eq!(snap.counters.timeouts, start.timeouts, "{model}: timeouts");
        assert!(snap.counters.polls > start.polls, "{model}: no polls");
        if model.is_latent() {
            assert!(
                snap.counters.frames_tx_batched > 0,
                "{model}: nothing batched"
            );
            // Written without waiting for each reply...
            let pipelined = snap.counters.polls_pipelined - start.polls_pipelined;
            assert!(pipelined > 0, "{model}: nothing pipelined");
            // ... and on a full-speed adapter (1 ms frames, far longer than
            // a host's wake-up), timed by the frame clock learnt from the
            // replies. A microframe (125 µs) may stay unknown on a loaded
            // host: the pipeline then holds the wire a microframe longer.
            let unclocked = snap.counters.usb_writes_unclocked - start.usb_writes_unclocked;
            if model.usb_frame() == Some(Duration::from_millis(1)) {
                assert!(unclocked < pipelined, "{model}: the clock never learnt");
            }
        }
    });
}

#[test]
fn every_adapter_model_keeps_every_joint_and_collides_nowhere() {
    for model in [
        AdapterModel::Native,
        AdapterModel::Ch340,
        AdapterModel::Cp2102,
        AdapterModel::Ftdi { latency_ms: 1 },
        AdapterModel::Ftdi { latency_ms: 16 },
        AdapterModel::Ft232h { latency_ms: 1 },
        AdapterModel::Ft232h { latency_ms: 16 },
    ] {
        stream_for_5_s_behind(model);
    }
}
