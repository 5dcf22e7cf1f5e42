//! Joint calibration (issue 18) against the simulator: an offset, a flip
//! and a range set through the API are applied in both directions, for
//! REST targets, moves, device views and WebSocket telemetry, while the
//! simulated device turns to the *device* angle they stand for; bad
//! calibrations and targets outside the range get a 4xx that says why.

mod support;

use std::sync::Arc;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use jointd::hands::StateStore;
use jointd::http::state::StateOptions;
use jointd::protocol::status::fsm;
use serde_json::{json, Value};
use support::sim_bus::{start, SimBus, WAIT};
use tokio_tungstenite::tungstenite::Message;

const CAL: &str = "/api/v1/buses/sim0/devices/1/calibration";

/// The API with an in-memory store for calibrations, joints 1..=n enabled.
async fn calibrated_rig(n: u8) -> SimBus {
    let b = start(n, None).await;
    let store = StateStore::open(Vec::new(), None).expect("store");
    b.server_state
        .set_options(StateOptions {
            hands: Some(Arc::new(store)),
            ..Default::default()
        })
        .map_err(|_| "options set twice")
        .unwrap();
    let ids: Vec<u8> = (1..=n).collect();
    b.server
        .post("/api/v1/buses/sim0/control/enable", json!({ "ids": ids }))
        .await
        .ok();
    for id in ids {
        b.wait_fsm(id, fsm::RUN).await;
    }
    b
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
            if let Some(j) = v["joints"].as_array().and_then(|js| {
                js.iter()
                    .find(|j| j["dev_id"] == 1 && j["target_deg"] == 30.0)
            }) {
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
