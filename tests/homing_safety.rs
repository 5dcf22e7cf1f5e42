//! Homing that cannot hurt: a joint with no hard stop ends `failed` inside
//! its soft range (or its `max_travel_deg`) with nothing saved; a joint
//! still aligning, or already being homed, is refused (409); a stop that
//! would read at the end of the angle range is refused (422); and
//! `current_limit_restored` is true only when the limit reads back as it
//! was.

mod support;

use std::time::Duration;

use jointd::protocol::status::fsm;
use serde_json::{json, Value};
use support::http::Server;
use support::sim_bus::{start_sim_with, SimBus, WAIT};

/// Joints 1..=n enabled and running, a store for calibrations. Joint 2
/// has soft limits of ±45° (the harness's), joint 1 none (±255°).
async fn rig(n: u8, hard_stops: Vec<(u8, f64)>) -> SimBus {
    start_sim_with(n, None, "2.0.1", |sim| sim.hard_stops = hard_stops, |_| {})
        .await
        .calibrated_and_enabled(n)
        .await
}

/// Polls homing job `id` until it is done; its view.
async fn homing_done(server: &Server, id: &Value) -> Value {
    let path = format!("/api/v1/homing/{id}");
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let view = server.get(&path).await.ok().clone();
        if view["state"] == "done" {
            return view;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "homing never done: {view}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn max_current_raw(b: &SimBus, id: u8) -> u16 {
    let dev = b.sim.device(id).expect("a device");
    dev.params.raw(jointd::protocol::params::index::MAX_CUR)
}

fn offset_of(cal: &Value) -> f64 {
    cal["offset_deg"].as_f64().expect("an offset")
}

/// Waits until the simulated joint stands (it coasts a little after speed 0).
async fn joint_stands(b: &SimBus, id: u8) {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let dev = b.sim.device(id).expect("a device");
        if dev.velocity_deg_s.abs() < 0.5 {
            return;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "joint {id} never stood: {} °/s",
            dev.velocity_deg_s
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_joint_with_no_hard_stop_ends_failed_inside_its_soft_range_with_nothing_saved() {
    let b = rig(2, Vec::new()).await;
    let before = max_current_raw(&b, 2);
    // Joint 2: soft limits ±45°, no stop anywhere.
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 2}], "speed_dps": 45.0}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let done = homing_done(&b.server, &r.body["id"]).await;
    let joint = &done["joints"][0];
    assert_eq!(joint["state"], "failed", "{done}");
    let reason = joint["reason"].as_str().unwrap_or_default();
    assert!(reason.contains("no hard stop within"), "{done}");
    assert!(reason.contains("soft limit"), "{done}");
    assert_eq!(joint["offset_deg"], Value::Null, "{done}");
    assert_eq!(joint["current_limit_restored"], true, "{done}");
    assert_eq!(max_current_raw(&b, 2), before);
    joint_stands(&b, 2).await;
    let dev = b.sim.device(2).expect("a device");
    assert!(
        dev.angle_deg >= -45.0 && dev.angle_deg < -30.0,
        "stopped inside the soft range, near its end: {}°",
        dev.angle_deg
    );
    assert_eq!(dev.spd_ref, 0);
    assert_eq!(dev.mode.to_string(), "position");
    let cal = b
        .server
        .get("/api/v1/buses/sim0/devices/2/calibration")
        .await;
    assert_eq!(offset_of(cal.ok()), 0.0, "nothing saved");

    // Joint 1 (±255°): max_travel_deg bounds it.
    let bad = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "max_travel_deg": 0.0}),
        )
        .await;
    assert_eq!(bad.problem(422)["field"], "max_travel_deg");
    let bad = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "max_travel_deg": 600.0}),
        )
        .await;
    assert_eq!(bad.problem(422)["allowed"]["max"], 510.0);
    let start = b.sim.device(1).expect("a device").angle_deg;
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "speed_dps": 45.0, "max_travel_deg": 20.0}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let done = homing_done(&b.server, &r.body["id"]).await;
    let joint = &done["joints"][0];
    assert_eq!(joint["state"], "failed", "{done}");
    assert!(
        joint["reason"]
            .as_str()
            .is_some_and(|r| r.contains("no hard stop within max_travel_deg = 20")),
        "{done}"
    );
    joint_stands(&b, 1).await;
    let travelled = start - b.sim.device(1).expect("a device").angle_deg;
    assert!(
        (10.0..=20.0).contains(&travelled),
        "turned {travelled}° of at most 20°"
    );
    let cal = b
        .server
        .get("/api/v1/buses/sim0/devices/1/calibration")
        .await;
    assert_eq!(offset_of(cal.ok()), 0.0, "nothing saved");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn homing_a_joint_that_still_aligns_is_refused() {
    // Alignment long enough that the request comes while it lasts.
    let b = start_sim_with(
        1,
        None,
        "2.0.1",
        |sim| sim.align_time = Duration::from_secs(60),
        |_| {},
    )
    .await;
    b.server
        .post("/api/v1/buses/sim0/control/enable", json!({"ids": [1]}))
        .await
        .ok();
    b.wait_fsm(1, fsm::ALIGN).await;
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}]}),
        )
        .await;
    let p = r.problem(409);
    assert_eq!(p["type"], "urn:jointd:problem:not-aligned", "{p}");
    assert!(
        p["detail"].as_str().is_some_and(|d| d.contains("align")),
        "{p}"
    );
    // Nothing was started: the joint still aligns in position mode.
    let dev = b.sim.device(1).expect("a device");
    assert_eq!(dev.mode.to_string(), "position");
    assert_eq!(b.server.get("/api/v1/homing/1").await.status.as_u16(), 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_homing_of_a_joint_being_homed_is_refused_naming_the_job() {
    let b = rig(1, vec![(1, -20.0)]).await;
    let body = json!({"joints": [{"bus": "sim0", "id": 1}], "speed_dps": 10.0});
    let first = b.server.post("/api/v1/homing", body.clone()).await;
    assert_eq!(first.status.as_u16(), 202, "{}", first.body);
    let job = first.body["id"].clone();
    let second = b.server.post("/api/v1/homing", body.clone()).await;
    let p = second.problem(409);
    assert_eq!(p["type"], "urn:jointd:problem:homing-running", "{p}");
    assert!(
        p["detail"]
            .as_str()
            .is_some_and(|d| d.contains(&format!("homing job {job}"))),
        "{p}"
    );
    let done = homing_done(&b.server, &job).await;
    assert_eq!(done["joints"][0]["state"], "homed", "{done}");
    assert_eq!(done["joints"][0]["current_limit_restored"], true, "{done}");
    // Once it is done, the joint may be homed again.
    let again = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "speed_dps": 10.0, "stop_at_deg": 0.0}),
        )
        .await;
    assert_eq!(again.status.as_u16(), 202, "{}", again.body);
    homing_done(&b.server, &again.body["id"]).await;
}

/// A homing speed is checked as every motion speed is: no slower than
/// the wire carries, within the joint's soft speed limit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_homing_speed_the_wire_cannot_carry_or_over_the_soft_limit_is_refused() {
    let b = rig(2, Vec::new()).await;
    let home = |id: u8, dps: f64| {
        b.server.post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": id}], "speed_dps": dps, "stop_at_deg": 0.0}),
        )
    };
    let r = home(1, 1e-300).await;
    assert_eq!(r.problem(422)["field"], "speed_dps", "{}", r.body);
    // Joint 2 may turn at 60 °/s at most.
    let r = home(2, 80.0).await;
    assert_eq!(
        r.problem(422)["type"],
        "urn:jointd:problem:soft-limit",
        "{}",
        r.body
    );
    assert_eq!(b.server.get("/api/v1/homing/1").await.status.as_u16(), 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stop_reading_at_the_end_of_the_range_is_refused_with_the_allowed_range() {
    let b = rig(2, Vec::new()).await;
    let at_end = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "stop_at_deg": 255.0}),
        )
        .await;
    let p = at_end.problem(422);
    assert_eq!(p["field"], "stop_at_deg");
    assert_eq!(
        p["allowed"],
        json!({"min": -225.0, "max": 225.0, "unit": "deg"})
    );
    // Joint 2's soft range is ±45°.
    let outside = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 2}], "stop_at_deg": 60.0}),
        )
        .await;
    let p = outside.problem(422);
    assert_eq!(p["field"], "stop_at_deg");
    assert_eq!(
        p["allowed"],
        json!({"min": -45.0, "max": 45.0, "unit": "deg"})
    );
    // Neither started anything.
    assert_eq!(b.server.get("/api/v1/homing/1").await.status.as_u16(), 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_current_limit_counts_as_restored_only_when_it_reads_back_as_it_was() {
    let bus = support::fake_bus::FakeBus::new("fake", &[1]);
    let state = jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            Default::default(),
        )),
        None,
    );
    let server = support::http::serve(state).await;
    server
        .post("/api/v1/buses/fake/control/enable", json!({"ids": [1]}))
        .await
        .ok();
    // The first read gives the previous limit (raw 4368, 0.75 A); every
    // read after the write-back shows another one, for a good while.
    bus.script().info04_max_current.push_back(4368);
    bus.script()
        .info04_max_current
        .extend(std::iter::repeat_n(1000, 10_000));
    // The fake joint never moves: the search times out at once.
    let body = json!({"joints": [{"bus": "fake", "id": 1}], "timeout_ms": 50.0});
    let r = server.post("/api/v1/homing", body.clone()).await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let done = homing_done(&server, &r.body["id"]).await;
    assert_eq!(done["joints"][0]["state"], "failed", "{done}");
    assert_eq!(done["joints"][0]["current_limit_restored"], false, "{done}");
    let reads = bus
        .script()
        .log
        .iter()
        .filter(|k| **k == "read_info")
        .count();
    assert!(reads >= 3, "the limit was read back: {reads} reads");
    // Owed: the joint's view says so, and no new motion is admitted.
    let dev = server.get("/api/v1/buses/fake/devices/1").await;
    assert_eq!(
        dev.ok()["current_limit_owed_a"],
        json!(0.7498397778252511),
        "{}",
        dev.body
    );
    let r = server.post("/api/v1/homing", body.clone()).await;
    assert_eq!(
        r.problem(409)["type"],
        "urn:jointd:problem:current-limit-owed"
    );
    // When a read-back shows the previous limit, the job says so, and the
    // joint may move again.
    bus.script().info04_max_current.clear();
    let path = format!("/api/v1/homing/{}", done["id"]);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while server.get(&path).await.ok()["joints"][0]["current_limit_restored"] != true {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the owed limit never went back"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let dev = server.get("/api/v1/buses/fake/devices/1").await;
    assert!(dev.ok()["current_limit_owed_a"].is_null(), "{}", dev.body);
    let r = server.post("/api/v1/homing", body).await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let done = homing_done(&server, &r.body["id"]).await;
    assert_eq!(done["joints"][0]["current_limit_restored"], true, "{done}");
}
