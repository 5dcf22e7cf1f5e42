//! Behind a USB adapter whose port says when the adapter took a write (the
//! in-memory line passes the simulated adapter's taking on, as a USB-serial
//! driver's output count does), writes that reach the adapter late, or
//! very late, never collide: the pipeline stays at its bound's mode,
//! confirms each write, and charges the late ones the frames they were
//! late. Counts and orderings only: every wait is on a condition.

mod support;

use std::time::Duration;

use jointd::bus::usb::guard::{PipelineMode, UsbPipelineView};
use jointd::bus::{AdapterSetting, BusSnapshot};
use jointd::sim::{Fault, WriteDelay};
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

const JOINTS: usize = 8;

/// One test of this file at a time: each runs a bus at its adapter's bound
/// beside a simulator.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn rig_behind(adapter: AdapterModel, ids: &[u8], confirm: bool) -> Rig {
    rig_on(Line::Memory, adapter, ids, confirm)
}

enum Line {
    Memory,
    /// In memory, the host waking this late after each wait on the port
    /// (a slow owner: it reads replies and the count that much late).
    MemoryWakingLate(Duration),
    /// Opened by path like hardware; the simulator publishes what the
    /// driver's count would say (a pty's own says 0 at once).
    Pty,
}

fn rig_on(line: Line, adapter: AdapterModel, ids: &[u8], confirm: bool) -> Rig {
    let mut sim_cfg = sim_config(ids, BAUD);
    sim_cfg.adapter = adapter;
    // The adapter's timing is hardware's (see tests/usb_backoff.rs).
    sim_cfg.realtime = true;
    let tune = |c: &mut jointd::bus::BusConfig| {
        c.ids = ids.to_vec();
        c.adapter = AdapterSetting::Fixed(adapter);
        c.timing.usb_confirm = confirm;
    };
    match line {
        Line::Memory => rig_on_memory(sim_cfg, tune),
        Line::MemoryWakingLate(late) => rig_on_memory_waking_late(sim_cfg, late, tune),
        Line::Pty => rig_with(sim_cfg, tune),
    }
}

fn view(s: &BusSnapshot) -> UsbPipelineView {
    s.usb_pipeline
        .clone()
        .expect("a pipeline view behind an adapter")
}

fn polls(s: &BusSnapshot) -> u64 {
    s.counters.polls
}

/// Streams targets through a clean path, then `delay`, then clean again:
/// no collision anywhere, no backoff, every joint online, and the late
/// writes seen taken late.
async fn no_write_collides(line: Line, adapter: AdapterModel, delay: &str) {
    let over_pty = matches!(line, Line::Pty);
    let _one = ONE_AT_A_TIME.lock().await;
    let ids: Vec<u8> = (1..=JOINTS as u8).collect();
    let rig = rig_on(line, adapter, &ids, true);
    rig.online(JOINTS).await;
    rig.enable_all(JOINTS).await;
    let stream = TargetStream::start(rig.bus.clone(), ids.clone(), Duration::from_millis(1));

    let start = rig.bus.snapshot();
    let clean = rig
        .until("writes confirmed and 200 polls", |s| {
            view(s).confirming && polls(s) >= polls(&start) + 200
        })
        .await;
    assert_eq!(view(&clean).mode, PipelineMode::Pipelined);
    assert_eq!(rig.sim.stats().collisions, 0);

    let delay = WriteDelay::parse(delay).expect("a delay");
    rig.sim.inject(Fault::WriteDelay(Some(delay)));
    let slipped_before = rig.sim.stats().host_writes_slipped;
    let late = rig
        .until("600 polls on the late path", |s| {
            polls(s) >= polls(&clean) + 600
        })
        .await;
    let st = rig.sim.stats();
    assert!(
        st.host_writes_slipped > slipped_before + 5,
        "the path was late: {} writes slipped a frame",
        st.host_writes_slipped - slipped_before
    );
    assert_eq!(st.collisions, 0, "a collision on the late path");
    let v = view(&late);
    if over_pty && v.mode != PipelineMode::Pipelined {
        // The simulator's own thread reads the pty: on a host that cannot
        // give it the real-time class, a stall of it is a write the
        // adapter did not take for the longest wait, which backs the
        // pipeline off (without a collision, asserted above).
        assert!(v.reason.contains("the port's output count"), "{v:?}");
        assert!(stream.finish() > 0);
        return;
    }
    assert_eq!(v.mode, PipelineMode::Pipelined, "backed off: {v:?}");
    assert!(v.confirming, "{v:?}");
    assert!(
        v.writes_taken_late > 0,
        "late writes seen taken late: {v:?}"
    );
    if !over_pty {
        // Decided at the host's write in memory: the delay (3 ms at most)
        // never keeps a write 4 ms. Over a pty its lag adds to the path.
        assert_eq!(v.counts_given_up, 0, "{v:?}");
    }
    assert_eq!(late.counters.usb_backoffs, 0);
    assert!(late.devices.values().all(|d| d.online));

    rig.sim.inject(Fault::WriteDelay(None));
    let after = rig
        .until("300 polls on a clean path again", |s| {
            polls(s) >= polls(&late) + 300
        })
        .await;
    assert_eq!(rig.sim.stats().collisions, 0);
    assert_eq!(view(&after).mode, PipelineMode::Pipelined);
    assert!(after.devices.values().all(|d| d.online));
    assert!(stream.finish() > 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn late_writes_never_collide_behind_a_ch340() {
    // Late by up to a whole USB frame, one in six past 0.85 ms: blind,
    // this path backs the pipeline off (tests/usb_backoff.rs).
    no_write_collides(Line::Memory, AdapterModel::Ch340, "600,1000,1000,1000").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn late_writes_never_collide_behind_a_slow_owner() {
    // An owner that wakes 150 µs late sees the count fall that late: the
    // write is still held until it is seen taken.
    no_write_collides(
        Line::MemoryWakingLate(Duration::from_micros(150)),
        AdapterModel::Ch340,
        "600,1000,1000,1000",
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn late_writes_never_collide_over_a_pty_either() {
    // The simulator's thread reading the pty is the adapter here.
    if !realtime_or_skip("late_writes_never_collide_over_a_pty_either") {
        return;
    }
    // The pty's own lag comes on top of the injected delay.
    no_write_collides(
        Line::Pty,
        AdapterModel::Ftdi { latency_ms: 1 },
        "600,1000,1000,1000",
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_path_late_by_milliseconds_never_collides_behind_an_ftdi_chip() {
    no_write_collides(
        Line::Memory,
        AdapterModel::Ftdi { latency_ms: 16 },
        "500,2000,3000",
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_are_confirmed_only_where_the_config_allows() {
    let _one = ONE_AT_A_TIME.lock().await;
    let ids: Vec<u8> = (1..=JOINTS as u8).collect();
    let rig = rig_behind(AdapterModel::Ch340, &ids, false);
    rig.online(JOINTS).await;
    let start = rig.bus.snapshot();
    let later = rig
        .until("200 polls", |s| polls(s) >= polls(&start) + 200)
        .await;
    let v = view(&later);
    assert!(!v.confirming, "{v:?}");
    assert_eq!(v.writes_taken_late, 0);
}
