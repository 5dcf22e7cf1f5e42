//! Every endpoint over HTTP against the real bus engine and the simulator on
//! a pty: what a user does, and each error status the wire can cause.

mod support;

use jointd::protocol::params::index;
use jointd::protocol::status::fsm;
use jointd::sim::Fault;
use serde_json::json;
use support::sim_bus::{start, start_sim_with, BUS};

const DEV: &str = "/api/v1/buses/sim0/devices";
/// Rotor speed (raw Q15) below which a joint counts as settled (~15 rpm).
const SETTLED_RAW_SPEED: i16 = 10;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn move_a_joint_end_to_end() {
    let b = start(4, None).await;
    let s = &b.server;
    let list = s.get(DEV).await;
    let devices = list.ok()["devices"].as_array().unwrap().clone();
    assert_eq!(devices.len(), 4);
    assert!(devices
        .iter()
        .all(|d| d["online"] == true && d["telemetry_age_ms"].is_number()));
    // Jog and target need an enabled joint.
    s.post(&format!("{DEV}/1/jog"), json!({"direction": "cw"}))
        .await
        .problem(409);
    s.put(&format!("{DEV}/1/target"), json!({"position_deg": 20}))
        .await
        .problem(409);
    s.post_empty(&format!("{DEV}/1/enable")).await.ok();
    b.wait_fsm(1, fsm::RUN).await;
    let r = s
        .put(
            &format!("{DEV}/1/target"),
            json!({"position_deg": 20, "speed_dps": 200}),
        )
        .await;
    assert_eq!(r.ok()["targets"][0]["pos_ref_raw"], 2560);
    b.wait_snapshot("joint 1 near 20°", |snap| {
        snap.devices[&1].info02.as_ref().is_some_and(|(i, _)| {
            (i.angle_deg() - 20.0).abs() < 0.5 && i.speed.abs() < SETTLED_RAW_SPEED
        })
    })
    .await;
    assert!((b.sim.device(1).unwrap().target_deg - 20.0).abs() < 1e-6);
    let d = s.get(&format!("{DEV}/1?fresh=true")).await;
    let d = d.ok();
    assert_eq!(d["status"]["state"], "run");
    assert_eq!(d["firmware"], "1.2.8");
    assert_eq!(d["status"]["fault"]["active"], "none");
    let angle = d["motion"]["angle_deg"].as_f64().unwrap();
    assert!((angle - 20.0).abs() < 0.5, "settled at {angle}°: {d}");
    // Jog, re-zero, disable.
    s.post(&format!("{DEV}/1/jog"), json!({"direction": "cw"}))
        .await
        .ok();
    s.post_empty(&format!("{DEV}/1/rezero")).await.ok();
    s.post_empty(&format!("{DEV}/1/disable")).await.ok();
    b.wait_fsm(1, fsm::READY).await;
    assert!(!b.sim.device(1).unwrap().enabled);
}

/// A joint aligning after its first enable stands still: a target then is
/// refused (409, saying to wait for `run`), on its own or in a group; once
/// it runs, the same target is taken and reached.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_target_while_the_joint_aligns_is_409_until_it_runs() {
    // Long enough that the requests come while it lasts on a loaded machine.
    let b = start_sim_with(
        2,
        None,
        "2.0.1",
        |sim| sim.align_time = std::time::Duration::from_secs(2),
        |_| {},
    )
    .await;
    let s = &b.server;
    s.post_empty(&format!("{DEV}/1/enable")).await.ok();
    b.wait_fsm(1, fsm::ALIGN).await;
    let target = json!({"position_deg": 20, "speed_dps": 200});
    let r = s.put(&format!("{DEV}/1/target"), target.clone()).await;
    let p = r.problem(409);
    assert_eq!(p["type"], "urn:jointd:problem:not-aligned", "{p}");
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.contains("aligning") && detail.contains("once its state is `run`"),
        "{p}"
    );
    let r = s
        .put(
            "/api/v1/buses/sim0/control/targets",
            json!({"targets": [{"id": 1, "position_deg": 20}]}),
        )
        .await;
    let p = r.problem(409);
    assert_eq!(p["type"], "urn:jointd:problem:not-aligned", "{p}");
    assert_eq!(p["field"], "targets[0]", "{p}");
    let d = s.get(&format!("{DEV}/1")).await;
    assert_eq!(d.ok()["status"]["state"], "align", "still aligning: {d:?}");
    // Nothing was stored: the joint runs without heading for 20°.
    b.wait_fsm(1, fsm::RUN).await;
    let held = b.sim.device(1).unwrap().target_deg;
    assert!((held - 20.0).abs() > 1.0, "target {held}° after the 409s");
    s.put(&format!("{DEV}/1/target"), target).await.ok();
    b.wait_snapshot("joint 1 near 20°", |snap| {
        snap.devices[&1]
            .info02
            .as_ref()
            .is_some_and(|(i, _)| (i.angle_deg() - 20.0).abs() < 0.5)
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn group_control_and_soft_limits() {
    let b = start(4, None).await;
    let s = &b.server;
    s.post(
        "/api/v1/buses/sim0/control/enable",
        json!({"ids": [1, 2, 3]}),
    )
    .await
    .ok();
    for id in 1..=3 {
        b.wait_fsm(id, fsm::RUN).await;
    }
    let too_far =
        json!({"targets": [{"id": 1, "position_deg": 10}, {"id": 2, "position_deg": 60}]});
    let r = s.put("/api/v1/buses/sim0/control/targets", too_far).await;
    let p = r.problem(422);
    assert_eq!(
        (p["field"].as_str(), p["allowed"]["max"].as_f64()),
        (Some("targets[1].position_deg"), Some(45.0))
    );
    let ok = json!({"targets": [{"id": 1, "position_deg": 10}, {"id": 2, "position_deg": -10}, {"id": 3, "position_deg": 5}]});
    s.put("/api/v1/buses/sim0/control/targets", ok).await.ok();
    b.wait_snapshot("three joints at their targets", |snap| {
        [(1u8, 10.0), (2, -10.0), (3, 5.0)].iter().all(|(id, deg)| {
            snap.devices[id]
                .info02
                .as_ref()
                .is_some_and(|(i, _)| (i.angle_deg() - deg).abs() < 0.5)
        })
    })
    .await;
    assert!(
        !b.sim.device(4).unwrap().enabled,
        "joint 4 was not addressed"
    );
    s.put(
        "/api/v1/buses/sim0/control/mode",
        json!({"ids": [3], "mode": "speed"}),
    )
    .await
    .ok();
    b.wait_snapshot("mode recorded", |snap| {
        snap.devices[&3].mode == Some(jointd::protocol::CtrlMode::Speed)
    })
    .await;
    s.put(&format!("{DEV}/3/target"), json!({"position_deg": 5}))
        .await
        .problem(422);
    s.put(&format!("{DEV}/3/target"), json!({"speed_dps": -10}))
        .await
        .ok();
    s.put(&format!("{DEV}/3/mode"), json!({"mode": "position"}))
        .await
        .ok();
    s.post("/api/v1/buses/sim0/control/disable", json!({}))
        .await
        .ok();
    for id in 1..=3 {
        b.wait_fsm(id, fsm::READY).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn configuration_read_change_persist_and_id() {
    let b = start(3, None).await;
    let s = &b.server;
    let c = s.get(&format!("{DEV}/2/config")).await;
    let before = c.ok().clone();
    assert!(before["max_current_a"]["raw"].is_u64() && before["max_current_a"]["unit"] == "A");
    let r = s
        .patch(
            &format!("{DEV}/2/config"),
            json!({"pos_kp": 1.5, "max_current_a": 1.5, "burst_plus_ms": 50}),
        )
        .await;
    let written = r.ok()["written"].as_array().unwrap().clone();
    assert_eq!(written.len(), 3);
    assert!(written.iter().all(|w| w["verified_by"].is_string()));
    let after = s.get(&format!("{DEV}/2/config")).await;
    let after = after.ok();
    assert_eq!(after["pos_kp"]["value"], 1.5);
    assert!((after["max_current_a"]["value"].as_f64().unwrap() - 1.5).abs() < 1e-3);
    assert_eq!(after["burst_plus_ms"]["value"], 50.0);
    s.patch(&format!("{DEV}/2/config"), json!({"burst_plus_ms": 30}))
        .await
        .problem(422);
    s.post_empty(&format!("{DEV}/2/config/persist")).await.ok();
    assert_eq!(
        b.sim.device(2).unwrap().flash.raw(index::MAX_CUR),
        b.sim.device(2).unwrap().params.raw(index::MAX_CUR)
    );
    s.put(&format!("{DEV}/3/id"), json!({"new_id": 1}))
        .await
        .problem(409);
    s.put(&format!("{DEV}/3/id"), json!({"new_id": 9}))
        .await
        .ok();
    b.wait_snapshot("id 9 on the bus", |snap| snap.devices.contains_key(&9))
        .await;
    s.get(&format!("{DEV}/9?fresh=true")).await.ok();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silent_device_is_504_unplugged_bus_is_503() {
    let b = start(2, None).await;
    let s = &b.server;
    b.sim.inject(Fault::DropReplies {
        dev_id: Some(2),
        rate: 1.0,
    });
    s.get(&format!("{DEV}/2?fresh=true")).await.problem(504);
    s.get(&format!("{DEV}/2/config")).await.problem(504);
    s.get(&format!("{DEV}/1?fresh=true")).await.ok();
    b.sim.inject(Fault::ClearAll);
    b.sim.inject(Fault::Unplug);
    b.wait_snapshot("bus down", |snap| {
        matches!(snap.link, jointd::bus::handle::LinkState::Down { .. })
    })
    .await;
    s.get("/readyz").await.problem(503);
    s.post_empty(&format!("{DEV}/1/enable")).await.problem(503);
    assert_eq!(s.get("/api/v1/buses/sim0").await.ok()["link"], "down");
    b.sim.inject(Fault::Replug);
    b.wait_snapshot("bus up", |snap| {
        snap.link == jointd::bus::handle::LinkState::Up
    })
    .await;
    s.get("/readyz").await.ok();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn estop_preempts_a_busy_bus() {
    let b = start(4, None).await;
    let s = &b.server;
    s.post("/api/v1/buses/sim0/control/enable", json!({}))
        .await
        .ok();
    for id in 1..=4 {
        b.wait_fsm(id, fsm::RUN).await;
    }
    // Keep the bus busy: scans of ids nobody has each wait out every timeout.
    let busy: Vec<_> = (0..3)
        .map(|_| {
            let (base, client) = (s.base.clone(), s.client.clone());
            tokio::spawn(async move {
                let url = format!("{base}/api/v1/buses/sim0/scan");
                client
                    .post(url)
                    .json(&json!({"first": 20, "last": 159}))
                    .send()
                    .await
                    .unwrap()
                    .status()
            })
        })
        .collect();
    b.wait_snapshot("requests queued", |snap| snap.queue_depth >= 1)
        .await;
    let r = s.post_empty("/api/v1/estop").await;
    let report = r.ok()["buses"][0].clone();
    assert_eq!(report["bus"], BUS);
    assert_eq!(report["stopped"], true);
    assert!(report["frames_sent"].as_u64().unwrap() >= 1);
    // Every joint was read back disabled before the call returned.
    assert_eq!(report["confirmed"], json!([1, 2, 3, 4]), "{report}");
    assert_eq!(report["unconfirmed"], json!([]));
    for id in 1..=4 {
        b.wait_fsm(id, fsm::READY).await;
        assert!(!b.sim.device(id).unwrap().enabled);
    }
    let mut statuses = Vec::new();
    for t in busy {
        statuses.push(t.await.unwrap().as_u16());
    }
    assert!(
        statuses.contains(&409),
        "queued scans are preempted: {statuses:?}"
    );
    s.post_empty("/api/v1/buses/sim0/estop").await.ok();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn buses_frames_scan_metrics_and_auth() {
    let b = start(3, Some("tok")).await;
    let s = &b.server;
    let anon = support::http::Server {
        token: None,
        base: s.base.clone(),
        client: s.client.clone(),
    };
    anon.get("/api/v1/buses").await.problem(401);
    anon.get("/healthz").await.ok();
    let buses = s.get("/api/v1/buses").await;
    assert_eq!(buses.ok()["buses"][0]["link"], "up");
    let found = s
        .post("/api/v1/buses/sim0/scan", json!({"first": 1, "last": 5}))
        .await;
    assert_eq!(found.ok()["found"], json!([1, 2, 3]));
    let frames = s.get("/api/v1/buses/sim0/frames?limit=10").await;
    let frames = frames.ok()["frames"].as_array().unwrap().clone();
    assert_eq!(frames.len(), 10);
    assert!(frames
        .iter()
        .any(|f| f["direction"] == "rx" && f["decoded"]["kind"] == "reply"));
    let m = s.get("/metrics").await;
    let text = m.body.as_str().unwrap().to_owned();
    assert!(text.contains("jointd_bus_up{bus=\"sim0\"} 1"));
    assert!(text.contains("jointd_bus_wire_utilisation_ratio{bus=\"sim0\"}"));
    assert!(text
        .lines()
        .any(|l| l.starts_with("jointd_bus_frames_rx_total{bus=\"sim0\"}") && !l.ends_with(" 0")));
    s.get("/api/v1/buses/sim0/devices/99").await.problem(404);
    s.get("/api/v1/buses/nope/devices").await.problem(404);
    s.get(&format!("{DEV}/abc")).await.problem(400);
    let r = s
        .put(&format!("{DEV}/1/target"), json!({"position_deg": 300}))
        .await;
    assert_eq!(r.problem(422)["field"], "position_deg");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn baud_change_end_to_end() {
    let b = start(2, None).await;
    let s = &b.server;
    let r = s
        .put("/api/v1/buses/sim0/baud", json!({"baud": 230400}))
        .await;
    assert_eq!(r.ok()["baud"], 230400);
    b.wait_snapshot("bus at 230400", |snap| snap.baud == 230400)
        .await;
    assert_eq!(s.get("/api/v1/buses/sim0").await.ok()["baud"], 230400);
    s.get(&format!("{DEV}/2?fresh=true")).await.ok();
    assert_eq!(b.sim.device(2).unwrap().baud, 230400);
}

/// What the daemon does on SIGTERM after the server stops: each bus owner
/// disables every joint before it closes the port.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stopping_the_bus_disables_every_joint() {
    let mut b = start(3, None).await;
    let s = &b.server;
    s.post("/api/v1/buses/sim0/control/enable", json!({}))
        .await
        .ok();
    for id in 1..=3 {
        b.wait_fsm(id, fsm::RUN).await;
    }
    let thread = b.thread.take().expect("bus thread");
    tokio::task::spawn_blocking(move || thread.stop())
        .await
        .unwrap();
    let deadline = std::time::Instant::now() + support::sim_bus::WAIT;
    while b.sim.devices().iter().any(|d| d.enabled) {
        assert!(
            std::time::Instant::now() < deadline,
            "joints still enabled after stop"
        );
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
}

/// Every reply lost (the device hears and acts, the host hears nothing):
/// each write goes out and is reported unverified (504
/// `write-unverified`), never "not written": the device has each value.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_whose_answers_are_lost_are_unverified_not_unwritten() {
    let b = start(1, None).await;
    let s = &b.server;
    b.sim.inject(Fault::DropReplies {
        dev_id: None,
        rate: 1.0,
    });
    let r = s
        .patch(
            &format!("{DEV}/1/config"),
            json!({"max_current_a": 1.5, "burst_plus_ms": 50}),
        )
        .await;
    let p = r.problem(504);
    assert_eq!(p["type"], "urn:jointd:problem:write-unverified", "{p}");
    let unverified = p["partial"]["unverified"].as_array().unwrap().clone();
    assert_eq!(unverified.len(), 2, "{p}");
    assert!(p["partial"]["written"].as_array().unwrap().is_empty());
    assert!(p["partial"]["not_written"].as_array().unwrap().is_empty());
    let dev = b.sim.device(1).unwrap();
    assert_eq!(
        u64::from(dev.params.raw(index::MAX_CUR)),
        unverified[0]["raw"].as_u64().unwrap()
    );
    assert_eq!(dev.params.raw(index::PLUS_TIME), 2);

    let r = s.post_empty(&format!("{DEV}/1/config/persist")).await;
    let p = r.problem(504);
    assert_eq!(p["type"], "urn:jointd:problem:write-unverified", "{p}");
    assert_eq!(b.sim.device(1).unwrap().flash.raw(index::PLUS_TIME), 2);

    // Neither the new id nor the old one answers: unverified, and the
    // device did change.
    let r = s.put(&format!("{DEV}/1/id"), json!({"new_id": 7})).await;
    let p = r.problem(504);
    assert_eq!(p["type"], "urn:jointd:problem:write-unverified", "{p}");
    assert!(b.sim.device(7).is_some());
    b.sim.inject(Fault::ClearAll);
    // Two parameters, the flash write and the id change.
    b.wait_snapshot("4 unverified writes counted", |s| {
        s.counters.writes_unverified == 4 && s.counters.verify_retries > 0
    })
    .await;
}
