//! Behind a latency timer an e-stop takes the wire from a transaction
//! whose reply is still held in the adapter. The transaction is given up
//! for the e-stop, not missed: its reply, when the adapter lets it go, is
//! taken in as a late one, and neither the device's record nor the USB
//! pipeline's evidence of lost replies counts it.

mod support;

use jointd::bus::error::BusError;
use jointd::bus::AdapterSetting;
use jointd::protocol::{Command, Config, InfoBlock};
use jointd::transport::adapter::AdapterModel;
use support::bus::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_transaction_given_up_for_an_estop_is_not_a_missed_reply() {
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
    // Evidence this soon after the pipeline started is not counted.
    rig.until("the pipeline settled", |s| {
        s.usb_pipeline.as_ref().is_some_and(|u| u.since_s > 0.2)
    })
    .await;

    let request = Command::Config(Config::read(2, InfoBlock::Info03)).encode();
    let before = rig.sim.frame_log().len();
    let bus = rig.bus.clone();
    let read = tokio::spawn(async move { bus.read_info(2, InfoBlock::Info03).await });
    let deadline = tokio::time::Instant::now() + WAIT;
    while !rig.sim.frame_log()[before..]
        .iter()
        .any(|f| f.from_host && f.bytes == request)
    {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the read never reached the wire"
        );
        tokio::task::yield_now().await;
    }
    let at_estop = rig.bus.snapshot();
    rig.bus.estop().await.expect("the e-stop");
    let read = tokio::time::timeout(WAIT, read)
        .await
        .expect("the read ended")
        .expect("the read's task");
    assert!(
        matches!(read, Err(BusError::Preempted)),
        "the read the e-stop cut short: {read:?}"
    );
    // The reply the e-stop did not wait for comes out of the adapter
    // later; a few turns after it is taken in, any evidence it made has
    // been acted on.
    let taken = rig
        .until("the abandoned reply taken in", |s| {
            s.counters.unsolicited > at_estop.counters.unsolicited
        })
        .await;
    let snap = rig
        .until("a few polls more", |s| {
            s.counters.polls > taken.counters.polls + 5
        })
        .await;
    let (c, c0) = (&snap.counters, &at_estop.counters);
    assert_eq!(c.timeouts, c0.timeouts, "counted as a timeout");
    assert_eq!(c.retries, c0.retries, "counted as a retry");
    assert_eq!(snap.devices[&2].missed_polls, 0, "counted as a missed poll");
    let usb = snap.usb_pipeline.as_ref().expect("a USB pipeline");
    assert_eq!(usb.backoffs, 0, "the pipeline backed off: {}", usb.reason);
    assert_eq!(usb.incidents_per_s, 0.0, "taken as evidence: {usb:?}");
}
