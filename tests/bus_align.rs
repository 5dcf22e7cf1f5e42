//! A target the bus is given while a joint aligns after its first enable
//! must still be reached once it runs. The front-ends refuse targets then
//! (409 `not-aligned`, `control::targets`); the bus keeps what it is given.

mod support;

use std::time::Duration;

use jointd::bus::Targets;
use jointd::protocol::status::fsm;
use support::bus::{rig_with, sim_config, target, BAUD};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_target_sent_during_align_is_reached() {
    let mut sim = sim_config(&[1], BAUD);
    sim.align_time = Duration::from_millis(400);
    let rig = rig_with(sim, |c| c.ids = vec![1]);
    rig.online(1).await;
    rig.bus.enable(Targets::Ids(vec![1])).await.expect("enable");
    assert_eq!(
        rig.sim.device(1).map(|d| d.fsm),
        Some(fsm::ALIGN),
        "still aligning"
    );
    rig.bus.set_targets(&[(1, target(12.0))]);
    rig.reaches(1, 12.0).await;
}
