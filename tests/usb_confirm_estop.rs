//! Confirmed writes never hold an e-stop back beyond the wait for the
//! write before it: behind an FTDI chip on its 16 ms timer, an e-stop
//! pressed while a transaction's reply waits in the adapter takes the wire
//! within a frame or two, however long the transaction had been waiting.
//! Latencies as the bus reports them; every wait is on a condition.

mod support;

use std::time::{Duration, Instant};

use jointd::bus::error::BusError;
use jointd::bus::AdapterSetting;
use jointd::protocol::{Command, Config, InfoBlock};
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

/// The 4 ms a count may stay up, and a frame: the longest an e-stop may
/// wait behind a write that waits to be seen taken.
const ESTOP_BOUND: Duration = Duration::from_millis(5);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_cutting_a_long_transaction_short_is_not_held_for_its_age() {
    let ids: Vec<u8> = (1..=4).collect();
    let adapter = AdapterModel::Ftdi { latency_ms: 16 };
    let mut sim_cfg = sim_config(&ids, BAUD);
    sim_cfg.adapter = adapter;
    sim_cfg.realtime = true;
    let rig = rig_on_memory(sim_cfg, |c| {
        c.ids = ids.clone();
        c.adapter = AdapterSetting::Fixed(adapter);
        c.timing.usb_confirm = true;
    });
    rig.online(4).await;
    rig.until("writes confirmed, the pipeline settled", |s| {
        s.usb_pipeline
            .as_ref()
            .is_some_and(|u| u.confirming && u.since_s > 0.2)
    })
    .await;

    // A read of a block the polls never ask for: its reply is known on
    // the wire, then held by the chip's timer for 16 ms.
    let request = Command::Config(Config::read(2, InfoBlock::Info03)).encode();
    let before = rig.sim.frame_log().len();
    let bus = rig.bus.clone();
    let read = tokio::spawn(async move { bus.read_info(2, InfoBlock::Info03).await });
    let deadline = Instant::now() + WAIT;
    let reply_end = loop {
        let log = rig.sim.frame_log();
        let asked = log
            .iter()
            .skip(before)
            .position(|f| f.from_host && f.bytes == request);
        let reply = asked.and_then(|i| {
            log[before + i + 1..]
                .iter()
                .find(|f| !f.from_host && f.dev_id == Some(2))
        });
        if let Some(reply) = reply {
            break reply.end;
        }
        assert!(Instant::now() < deadline, "the read was never answered");
        tokio::task::yield_now().await;
    };
    // Half the timer on: the reply has long left the wire and still waits
    // in the chip; the transaction has been waiting that long.
    let press_at = reply_end + Duration::from_millis(8);
    while Instant::now() < press_at {
        tokio::task::yield_now().await;
    }
    let report = rig.bus.estop().await.expect("the e-stop");
    let read = tokio::time::timeout(WAIT, read)
        .await
        .expect("the read ended")
        .expect("the read's task");
    assert!(
        matches!(read, Err(BusError::Preempted)),
        "the e-stop cut the read short: {read:?}"
    );
    let latency = Duration::from_micros(report.latency_us);
    assert!(
        latency < ESTOP_BOUND,
        "the e-stop waited {latency:?} to be handed over: {report:?}"
    );
}
