//! Joint calibration and homing against the simulator: an
//! offset, a flip and a range set through the API are applied in both
//! directions, for REST targets, moves, device views and WebSocket
//! telemetry, while the simulated device turns to the *device* angle they
//! stand for; bad calibrations and targets outside the range get a 4xx that
//! says why. Homing finds the simulator's hard stop and records it, and
//! puts the joint's current limit back after an e-stop mid-search.

mod support;

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use support::sim_bus::{start, start_sim_with, SimBus, WAIT};
use tokio_tungstenite::tungstenite::Message;

const CAL: &str = "/api/v1/buses/sim0/devices/1/calibration";

/// The API with an in-memory store for calibrations, joints 1..=n enabled.
async fn calibrated_rig(n: u8) -> SimBus {
    start(n, None).await.calibrated_and_enabled(n).await
}

/// [`calibrated_rig`] with joint 1's hard stop at `stop_deg`.
async fn rig_with_hard_stop(n: u8, stop_deg: f64) -> SimBus {
    let b = start_sim_with(
        n,
        None,
        "2.0.1",
        |sim| sim.hard_stops = vec![(1, stop_deg)],
        |_| {},
    )
    .await;
    b.calibrated_and_enabled(n).await
}

/// Waits until the simulated device's own angle is within 0.5° of `deg`.
async fn device_reaches(b: &SimBus, id: u8, deg: f64) {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let angle = b.sim.device(id).expect("a device").angle_deg;
        if (angle - deg).abs() < 0.5 {
            return;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "device {id} at {angle}°, never reached {deg}°"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Polls the device's view until the angle it reports is within 0.5° of
/// `deg` (the joint settles after the device is first seen there).
async fn view_reads(b: &SimBus, id: u8, deg: f64) -> Value {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let r = b
            .server
            .get(&format!("/api/v1/buses/sim0/devices/{id}"))
            .await;
        let view = r.ok().clone();
        if near(&view["status"]["angle_deg"], deg) && near(&view["motion"]["angle_deg"], deg) {
            return view;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "device {id} never read {deg}°: {view}"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

fn near(v: &Value, deg: f64) -> bool {
    v.as_f64().is_some_and(|x| (x - deg).abs() < 0.5)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibrated_joint_takes_and_reports_joint_angles() {
    let b = calibrated_rig(2).await;
    let identity = b.server.get(CAL).await.ok().clone();
    assert_eq!(identity["offset_deg"], 0.0);
    assert_eq!(identity["flip"], false);
    assert_eq!(identity["range_deg"], Value::Null);

    // joint = -(device - 10): joint 15° is the device's -5°.
    let set = b
        .server
        .put(
            CAL,
            json!({"offset_deg": 10.0, "flip": true, "range_deg": [-20.0, 40.0]}),
        )
        .await;
    assert_eq!(set.ok()["offset_deg"], 10.0);
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 15.0}),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    assert_eq!(r.body["targets"][0]["position_deg"], 15.0);
    device_reaches(&b, 1, -5.0).await;

    let view = view_reads(&b, 1, 15.0).await;
    assert_eq!(view["target"]["position_deg"], 15.0);
    assert_eq!(view["calibration"]["flip"], true);
    // ±255° device range seen from the joint: 10 - 255 .. 10 + 255, flipped.
    assert_eq!(view["limits"]["min_deg"], -245.0);
    assert_eq!(view["limits"]["max_deg"], 265.0);
    // Joint 2 has no calibration: its views are the device's.
    let other = b.server.get("/api/v1/buses/sim0/devices/2").await;
    assert_eq!(other.ok()["calibration"], Value::Null);

    // Outside the calibrated range: refused whole, said in joint degrees.
    let refused = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 41.0}),
        )
        .await;
    let p = refused.problem(422);
    assert_eq!(p["type"], "urn:jointd:problem:calibrated-range");
    assert_eq!(p["field"], "position_deg");
    assert!(p["detail"].as_str().unwrap().contains("-20..=40"), "{p}");

    // A move in joint degrees: planned and streamed as device angles.
    let mv = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 30.0}],
                   "duration_ms": 300, "method": "min_jerk"}),
        )
        .await;
    assert_eq!(mv.status.as_u16(), 201, "{}", mv.body);
    let move_path = format!("/api/v1/moves/{}", mv.body["id"]);
    let deadline = tokio::time::Instant::now() + WAIT;
    while b.server.get(&move_path).await.ok()["state"] != "done" {
        assert!(tokio::time::Instant::now() < deadline, "move never done");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    device_reaches(&b, 1, -20.0).await;
    let too_far = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": -25.0}], "duration_ms": 300}),
        )
        .await;
    assert_eq!(
        too_far.problem(422)["type"],
        "urn:jointd:problem:calibrated-range"
    );

    // WebSocket telemetry reports the joint's angle too.
    let url = format!("{}/api/v1/ws", b.server.base.replace("http://", "ws://"));
    let (mut ws, _) = tokio_tungstenite::connect_async(url).await.expect("ws");
    let sub = json!({"type": "subscribe", "fields": ["angle_deg", "target_deg"], "rate_hz": 50});
    ws.send(Message::text(sub.to_string())).await.expect("send");
    let joint1 = tokio::time::timeout(WAIT, async {
        loop {
            let Some(Ok(Message::Text(t))) = ws.next().await else {
                panic!("socket closed");
            };
            let v: Value = serde_json::from_str(t.as_str()).expect("json");
            if v["type"] != "telemetry" {
                continue;
            }
            // The first messages may predate the move's last frame.
            if let Some(j) = v["joints"]
                .as_array()
                .and_then(|js| js.iter().find(|j| j["id"] == 1 && j["target_deg"] == 30.0))
            {
                return j.clone();
            }
        }
    })
    .await
    .expect("telemetry");
    assert!(near(&joint1["angle_deg"], 30.0), "{joint1}");

    // Cleared: the device's frame again.
    let was = b.server.call(reqwest::Method::DELETE, CAL, None).await;
    assert_eq!(was.ok()["offset_deg"], 10.0);
    view_reads(&b, 1, -20.0).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_that_cannot_apply_is_refused_with_the_field() {
    let b = calibrated_rig(1).await;
    let far = b.server.put(CAL, json!({"offset_deg": 300.0})).await;
    assert_eq!(far.problem(422)["field"], "offset_deg");
    let upside_down = b.server.put(CAL, json!({"range_deg": [10.0, -10.0]})).await;
    assert_eq!(upside_down.problem(422)["field"], "range_deg");
    let unknown = b.server.put(CAL, json!({"offset": 3.0})).await;
    assert_eq!(
        unknown.problem(422)["type"],
        "urn:jointd:problem:invalid-body"
    );
    let no_joint = b
        .server
        .put(
            "/api/v1/buses/nope/devices/1/calibration",
            json!({"offset_deg": 1.0}),
        )
        .await;
    assert_eq!(no_joint.status.as_u16(), 404, "{}", no_joint.body);
    // Nothing was saved by any of them.
    assert_eq!(b.server.get(CAL).await.ok()["offset_deg"], 0.0);
}

/// Polls homing job `id` until it is done; its view.
async fn homing_done(b: &SimBus, id: &Value) -> Value {
    let path = format!("/api/v1/homing/{id}");
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let view = b.server.get(&path).await.ok().clone();
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn homing_finds_the_hard_stop_and_records_it() {
    let b = rig_with_hard_stop(2, -30.0).await;
    let before = max_current_raw(&b, 1);
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "direction": "negative",
                   "speed_dps": 30.0, "backoff_deg": 2.0, "stop_at_deg": 0.0}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    assert_eq!(r.body["joints"][0]["state"], "running");
    let done = homing_done(&b, &r.body["id"]).await;
    let joint = &done["joints"][0];
    assert_eq!(joint["state"], "homed", "{done}");
    assert!(near(&joint["hard_stop_device_deg"], -30.0), "{done}");
    assert_eq!(joint["current_limit_restored"], true);
    assert_eq!(max_current_raw(&b, 1), before, "the current limit is back");
    let cal = b.server.get(CAL).await.ok().clone();
    assert!(near(&cal["offset_deg"], -30.0), "{cal}");
    assert!(cal["homed_at_ms"].is_u64(), "{cal}");
    // Backed off by 2°: the joint reads 2° in its new frame, in position mode.
    device_reaches(&b, 1, -28.0).await;
    view_reads(&b, 1, 2.0).await;
    assert_eq!(
        b.sim.device(1).expect("a device").mode.to_string(),
        "position"
    );
    // Joint 2 has no stop and was not asked: untouched.
    assert_eq!(
        b.server
            .get("/api/v1/buses/sim0/devices/2/calibration")
            .await
            .ok()["offset_deg"],
        0.0
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_mid_homing_aborts_it_and_the_current_limit_is_restored() {
    // A stop too far to reach before the e-stop.
    let b = rig_with_hard_stop(1, -200.0).await;
    let before = max_current_raw(&b, 1);
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "speed_dps": 10.0, "current_limit_a": 0.25}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    // Wait until it searches under the reduced limit, then e-stop.
    let deadline = tokio::time::Instant::now() + WAIT;
    while !(max_current_raw(&b, 1) < before
        && b.sim.device(1).expect("a device").velocity_deg_s < -5.0)
    {
        assert!(tokio::time::Instant::now() < deadline, "never searched");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    b.server.post_empty("/api/v1/estop").await;
    let done = homing_done(&b, &r.body["id"]).await;
    let joint = &done["joints"][0];
    assert_eq!(joint["state"], "aborted", "{done}");
    assert_eq!(joint["reason"], "e-stop", "{done}");
    assert_eq!(joint["current_limit_restored"], true, "{done}");
    assert_eq!(max_current_raw(&b, 1), before, "the current limit is back");
    let dev = b.sim.device(1).expect("a device");
    assert!(!dev.enabled, "the e-stop disabled it");
    assert_eq!(dev.mode.to_string(), "position");
    // Nothing recorded.
    assert_eq!(b.server.get(CAL).await.ok()["offset_deg"], 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn homing_refuses_what_it_cannot_do_safely() {
    let b = calibrated_rig(1).await;
    let above = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "speed_dps": 500.0}),
        )
        .await;
    assert_eq!(above.problem(422)["field"], "speed_dps");
    let neither = b.server.post("/api/v1/homing", json!({})).await;
    assert_eq!(neither.problem(422)["field"], "joints");
    // A limit above the joint's own (0.75 A) would not reduce anything.
    let r = b
        .server
        .post(
            "/api/v1/homing",
            json!({"joints": [{"bus": "sim0", "id": 1}], "current_limit_a": 2.0}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let done = homing_done(&b, &r.body["id"]).await;
    assert_eq!(done["joints"][0]["state"], "failed");
    assert!(
        done["joints"][0]["reason"]
            .as_str()
            .unwrap()
            .contains("not below"),
        "{done}"
    );
    let missing = b.server.get("/api/v1/homing/999").await;
    assert_eq!(
        missing.problem(404)["type"],
        "urn:jointd:problem:unknown-homing"
    );
}
