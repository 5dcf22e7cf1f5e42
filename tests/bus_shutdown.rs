//! The safe state a stopping bus leaves its joints in (`on_shutdown`):
//! disabled by default, or still enabled holding their target.

mod support;

use std::time::Duration;

use jointd::bus::{AdapterSetting, ShutdownState};
use jointd::protocol::status::fsm;
use jointd::transport::adapter::AdapterModel;
use support::bus::{rig_on_memory, rig_with, sim_config, target, Rig, TargetStream, BAUD};

const IDS: [u8; 2] = [1, 2];

/// Two joints enabled and moving, then the bus stopped.
async fn stopped_with(state: ShutdownState) -> Rig {
    let mut rig = rig_with(sim_config(&IDS, BAUD), |c| {
        c.ids = IDS.to_vec();
        c.on_shutdown = state;
    });
    rig.online(IDS.len()).await;
    rig.enable_all(IDS.len()).await;
    rig.bus.set_targets(&[(1, target(10.0)), (2, target(-5.0))]);
    rig.reaches(1, 10.0).await;
    rig.stop();
    rig
}

fn states(rig: &Rig) -> Vec<u8> {
    IDS.iter()
        .filter_map(|id| rig.sim.device(*id))
        .map(|d| d.fsm)
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stopping_disables_every_joint_by_default() {
    let rig = stopped_with(ShutdownState::Disable).await;
    // The owner has written the disable when it stops; the simulator takes
    // it in on its own thread, later on a busy host.
    rig.sim_until("the shutdown's disable taken in", |sim| {
        IDS.iter()
            .all(|&id| sim.device(id).is_some_and(|d| !d.enabled))
    });
    assert_eq!(states(&rig), vec![fsm::READY, fsm::READY]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hold_leaves_the_joints_enabled() {
    let rig = stopped_with(ShutdownState::Hold).await;
    assert_eq!(states(&rig), vec![fsm::RUN, fsm::RUN]);
}

/// Behind a USB adapter polls go out blind, their replies still coming
/// when the owner stops: the shutdown's disable waits for the line as an
/// e-stop does, and collides with none of them. Several stops, each with
/// replies in flight (a stream of targets keeps the pipeline full).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shutdown_disable_waits_for_the_line_behind_a_usb_adapter() {
    let ids: Vec<u8> = (1..=8).collect();
    let ftdi = AdapterModel::Ftdi { latency_ms: 16 };
    for round in 0..5 {
        let mut sim_cfg = sim_config(&ids, BAUD);
        sim_cfg.adapter = ftdi;
        let mut rig = rig_on_memory(sim_cfg, |c| {
            c.ids = ids.clone();
            c.adapter = AdapterSetting::Fixed(ftdi);
            c.on_shutdown = ShutdownState::Disable;
        });
        rig.online(ids.len()).await;
        rig.enable_all(ids.len()).await;
        let stream = TargetStream::start(rig.bus.clone(), ids.clone(), Duration::from_millis(2));
        let before = rig.bus.snapshot().counters.frames_rx;
        rig.until("replies coming while the stream runs", |s| {
            s.counters.frames_rx > before + 50
        })
        .await;
        rig.stop();
        stream.finish();
        rig.sim_until("every joint disabled", |sim| {
            ids.iter()
                .all(|&id| sim.device(id).is_some_and(|d| !d.enabled))
        });
        eprintln!("round {round}");
        rig.assert_no_collisions();
    }
}
