//! Behind a USB adapter with a latency timer a transaction's reply leaves
//! the wire long before the adapter hands it over (16 ms later on an FTDI
//! chip's default timer). An e-stop pressed meanwhile takes the wire once
//! the reply is off it, not once the host has read it. Orderings on the
//! simulator's wire only: the e-stop's first frame against the moment the
//! adapter releases the reply.

mod support;

use std::time::Duration;

use jointd::bus::AdapterSetting;
use jointd::protocol::{Command, Config, InfoBlock};
use jointd::sim::WireFrame;
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

const TIMER: Duration = Duration::from_millis(16);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_during_a_transaction_does_not_wait_out_the_latency_timer() {
    let ids: Vec<u8> = (1..=4).collect();
    let adapter = AdapterModel::Ftdi { latency_ms: 16 };
    let mut sim_cfg = sim_config(&ids, BAUD);
    sim_cfg.adapter = adapter;
    sim_cfg.realtime = true;
    let rig = rig_on_memory(sim_cfg, |c| {
        c.ids = ids.clone();
        c.adapter = AdapterSetting::Fixed(adapter);
    });
    rig.online(4).await;

    // A one-shot read of a block the polls never ask for, so its frame
    // is known on the wire.
    let request = Command::Config(Config::read(2, InfoBlock::Info03)).encode();
    let before = rig.sim.frame_log().len();
    let bus = rig.bus.clone();
    let read = tokio::spawn(async move { bus.read_info(2, InfoBlock::Info03).await });
    let on_wire = |log: &[WireFrame]| {
        log.iter()
            .skip(before)
            .position(|f| f.from_host && f.bytes == request)
            .map(|i| before + i)
    };
    let deadline = tokio::time::Instant::now() + WAIT;
    let asked = loop {
        if let Some(i) = on_wire(&rig.sim.frame_log()) {
            break i;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the read never reached the wire"
        );
        tokio::task::yield_now().await;
    };
    let report = rig.bus.estop().await.expect("the e-stop");
    assert!(report.frames_sent > 0, "{report:?}");

    let log = rig.sim.frame_log();
    let reply = log[asked + 1..]
        .iter()
        .find(|f| !f.from_host && f.dev_id == Some(2))
        .expect("the device answered the read");
    let estop = log[asked + 1..]
        .iter()
        .find(|f| f.from_host)
        .expect("the e-stop's frames");
    assert!(
        estop.start >= reply.end,
        "the e-stop went out over the reply"
    );
    assert!(
        estop.start < reply.end + TIMER,
        "the e-stop waited {:?} after the reply left the wire, past the adapter's {TIMER:?} hold",
        estop.start - reply.end
    );
    // The read itself ends one way or the other, never hangs.
    let _ = tokio::time::timeout(WAIT, read)
        .await
        .expect("the read ended");
}
