//! The safe state a stopping bus leaves its joints in (`on_shutdown`):
//! disabled by default, or still enabled holding their target.

mod support;

use jointd::bus::ShutdownState;
use jointd::protocol::status::fsm;
use support::bus::{rig_with, sim_config, target, BAUD};

async fn stop_with(state: ShutdownState) -> Vec<u8> {
    let ids = [1u8, 2];
    let mut rig = rig_with(sim_config(&ids, BAUD), |c| {
        c.ids = ids.to_vec();
        c.on_shutdown = state;
    });
    rig.online(ids.len()).await;
    rig.enable_all(ids.len()).await;
    rig.bus.set_targets(&[(1, target(10.0)), (2, target(-5.0))]);
    rig.reaches(1, 10.0).await;
    rig.stop();
    ids.iter()
        .filter_map(|id| rig.sim.device(*id))
        .map(|d| d.fsm)
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stopping_disables_every_joint_by_default() {
    assert_eq!(
        stop_with(ShutdownState::Disable).await,
        vec![fsm::READY, fsm::READY]
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hold_leaves_the_joints_enabled() {
    assert_eq!(
        stop_with(ShutdownState::Hold).await,
        vec![fsm::RUN, fsm::RUN]
    );
}
