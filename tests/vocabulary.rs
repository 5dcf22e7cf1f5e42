//! One vocabulary: a joint's quantities have the same names and units on
//! REST and the WebSocket (docs/vocabulary.md), and the API's schemas carry
//! no rotor rpm or protocol-level names outside fields that say they are raw.

mod support;

use std::collections::BTreeSet;

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio_tungstenite::connect_async;
use tokio_tungstenite::tungstenite::Message;

use jointd::http::api;
use jointd::protocol::status::fsm;
use support::sim_bus::{self, SimBus, WAIT};

/// The speed joint 1 is driven at, output °/s.
const SPEED_DPS: f64 = 20.0;
/// The simulated joint settles on its speed within this.
const SPEED_TOLERANCE_DPS: f64 = 1.5;

/// Fields only one surface has: the WebSocket's per-message bookkeeping.
const WS_ONLY: &[&str] = &["bus", "age_ms", "target_deg", "fault", "name"];

async fn rest_joint(b: &SimBus, id: u64) -> Value {
    let list = b.server.get("/api/v1/buses/sim0/devices").await;
    let joints = list.ok()["devices"].as_array().cloned().unwrap_or_default();
    joints
        .into_iter()
        .find(|j| j["id"].as_u64() == Some(id))
        .unwrap_or(Value::Null)
}

fn near(v: &Value, want: f64) -> bool {
    v.as_f64()
        .is_some_and(|x| (x - want).abs() < SPEED_TOLERANCE_DPS)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_and_websocket_name_and_scale_a_joint_alike() {
    let b = sim_bus::start(2, None).await;
    let s = &b.server;
    s.post_empty("/api/v1/buses/sim0/devices/1/enable")
        .await
        .ok();
    b.wait_fsm(1, fsm::RUN).await;
    s.put(
        "/api/v1/buses/sim0/devices/1/mode",
        json!({"mode": "speed"}),
    )
    .await
    .ok();
    b.wait_snapshot("speed mode", |snap| {
        snap.devices[&1].mode == Some(jointd::protocol::CtrlMode::Speed)
    })
    .await;
    let ack = s
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"speed_dps": SPEED_DPS}),
        )
        .await;
    let echoed = ack.ok()["targets"][0]["speed_dps"].clone();
    assert!(near(&echoed, SPEED_DPS), "target echoed as {echoed}");

    // REST: the joint turns at the asked output speed, in the same unit.
    let rest = tokio::time::timeout(WAIT, async {
        loop {
            let j = rest_joint(&b, 1).await;
            if near(&j["speed_dps"], SPEED_DPS) {
                return j;
            }
            tokio::time::sleep(std::time::Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("REST shows joint 1 at its speed");

    // The WebSocket says the same under the same names.
    let url = format!("{}/api/v1/ws", s.base.replace("http://", "ws://"));
    let (mut ws, _) = connect_async(url).await.expect("connect");
    ws.send(Message::text(
        json!({"type": "subscribe", "devices": [1], "rate_hz": 50}).to_string(),
    ))
    .await
    .expect("subscribe");
    let sample = tokio::time::timeout(WAIT, async {
        while let Some(Ok(msg)) = ws.next().await {
            let Ok(text) = msg.to_text() else { continue };
            let v: Value = serde_json::from_str(text).unwrap_or(Value::Null);
            let joint = &v["joints"][0];
            if v["type"] == "telemetry" && near(&joint["speed_dps"], SPEED_DPS) {
                return joint.clone();
            }
        }
        Value::Null
    })
    .await
    .expect("telemetry shows joint 1 at its speed");
    assert_eq!(sample["id"], 1, "{sample}");
    assert_eq!(sample["state"], rest["state"], "{sample} vs {rest}");
    assert_eq!(sample["state"], "run");

    let ws_keys: BTreeSet<&str> = sample
        .as_object()
        .map(|o| o.keys().map(String::as_str).collect())
        .unwrap_or_default();
    let rest_keys: BTreeSet<&str> = rest
        .as_object()
        .map(|o| o.keys().map(String::as_str).collect())
        .unwrap_or_default();
    let unmatched: Vec<&str> = ws_keys
        .difference(&rest_keys)
        .filter(|k| !WS_ONLY.contains(k))
        .copied()
        .collect();
    assert!(
        unmatched.is_empty(),
        "telemetry fields REST names otherwise (or not at all): {unmatched:?}; REST has {rest_keys:?}"
    );

    s.put(
        "/api/v1/buses/sim0/devices/1/target",
        json!({"speed_dps": 0}),
    )
    .await
    .ok();
    s.post_empty("/api/v1/buses/sim0/devices/1/disable")
        .await
        .ok();
    b.wait_fsm(1, fsm::READY).await;
}

/// Every property of every schema in the OpenAPI document.
fn properties(v: &Value, out: &mut Vec<(String, String)>, schema: &str) {
    match v {
        Value::Object(o) => {
            if let Some(Value::Object(props)) = o.get("properties") {
                out.extend(props.keys().map(|k| (schema.to_owned(), k.clone())));
            }
            for val in o.values() {
                properties(val, out, schema);
            }
        }
        Value::Array(a) => a.iter().for_each(|x| properties(x, out, schema)),
        _ => {}
    }
}

#[test]
fn the_api_speaks_output_degrees_and_protocol_names_stay_in_raw_frames() {
    let doc: Value = serde_json::from_str(&api::document_json()).expect("JSON");
    let mut props = Vec::new();
    for (name, schema) in doc["components"]["schemas"].as_object().expect("schemas") {
        properties(schema, &mut props, name);
    }
    // Rotor rpm only where the name says rotor, or as the device parameter.
    let raw_rpm = ["rotor_speed_rpm", "spd_limit_rpm"];
    let wrong: Vec<_> = props
        .iter()
        .filter(|(_, p)| {
            (p.contains("rpm") && !raw_rpm.contains(&p.as_str()))
                || ["dev_id", "fsm", "current_a", "output_deg_per_s"].contains(&p.as_str())
        })
        .collect();
    assert!(wrong.is_empty(), "outside the vocabulary: {wrong:?}");
}
