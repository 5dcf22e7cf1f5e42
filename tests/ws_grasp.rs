//! Grasps over the WebSocket (`jointd.ws.v1`): `grasp` starts one like the
//! REST POST (answered `grasp_started` with the job), contact comes as a
//! `grasp_contact` event, `grasp_release` and `grasp_stop` end it
//! (answered once every finger ended, while the connection keeps
//! answering other messages), the connection that started it gets
//! `grasp_done` however it ended (an e-stop included: every finger
//! aborted, limits restored), and bad grasp messages are errors that say
//! what was wrong.

mod grasp_rig;
mod support;

use futures_util::{SinkExt, StreamExt};
use grasp_rig::{finger, hand, limits_restored, state_of, wait_grasp};
use serde_json::{json, Value};
use support::sim_bus::{SimBus, WAIT};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

async fn connect(b: &SimBus) -> Ws {
    let url = format!("{}/api/v1/ws", b.server.base.replace("http://", "ws://"));
    tokio_tungstenite::connect_async(url).await.expect("ws").0
}

async fn send(ws: &mut Ws, v: Value) {
    ws.send(Message::text(v.to_string())).await.expect("send");
}

/// Messages until one satisfies `ok` (within the tests' bound); that one
/// and every one before it.
async fn until(ws: &mut Ws, what: &str, ok: impl Fn(&Value) -> bool) -> (Value, Vec<Value>) {
    let mut seen = Vec::new();
    let found = tokio::time::timeout(WAIT * 2, async {
        loop {
            let msg = ws.next().await.expect("socket open").expect("message");
            if let Message::Text(t) = msg {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                if ok(&v) {
                    return v;
                }
                seen.push(v);
            }
        }
    })
    .await;
    match found {
        Ok(v) => (v, seen),
        Err(_) => panic!("timed out waiting for {what}; seen: {seen:?}"),
    }
}

fn of_type(t: &'static str) -> impl Fn(&Value) -> bool {
    move |v| v["type"] == t
}

/// A grasp of fingers a and c, c closing to `c_to` degrees.
fn grasp_msg(seq: u64, c_to: f64) -> Value {
    json!({"type": "grasp", "seq": seq, "hand": "h", "speed_dps": 30.0, "hold_current_a": 0.2,
           "joints": [{"joint": "a", "close_to_deg": 40.0}, {"joint": "c", "close_to_deg": c_to}]})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_grasp_started_over_the_websocket_holds_and_is_released_there() {
    // An object before finger a, nothing before c.
    let b = hand(&[(1, 12.0, 0.05)]).await;
    let mut ws = connect(&b).await;
    send(&mut ws, grasp_msg(7, 20.0)).await;
    let (started, _) = until(&mut ws, "grasp_started", of_type("grasp_started")).await;
    assert_eq!(started["ref_seq"], 7, "{started}");
    let id = started["grasp"]["id"].as_u64().expect("a grasp id");
    assert_eq!(started["grasp"]["hand"], "h", "{started}");
    assert_eq!(
        started["grasp"]["fingers"].as_array().map(Vec::len),
        Some(2)
    );
    // The same job REST shows.
    let rest = b.server.get(&format!("/api/v1/grasps/{id}")).await;
    assert_eq!(rest.ok()["id"], id);

    let (contact, _) = until(&mut ws, "a grasp_contact event", |v| {
        v["type"] == "event" && v["event"]["event"] == "grasp_contact"
    })
    .await;
    assert_eq!(contact["event"]["grasp_id"], id, "{contact}");
    assert_eq!(contact["event"]["id"], 1, "{contact}");
    let deg = contact["event"]["contact_deg"]
        .as_f64()
        .expect("contact_deg");
    assert!((10.0..14.0).contains(&deg), "{contact}");
    wait_grasp(&b, id, "a holding, c without contact", |v| {
        state_of(v, "a") == "holding" && state_of(v, "c") == "no_contact"
    })
    .await;

    // Release over the WebSocket; a ping sent after it is answered while
    // the fingers still open (the connection keeps reading).
    send(
        &mut ws,
        json!({"type": "grasp_release", "seq": 8, "id": id, "open_deg": 10.0}),
    )
    .await;
    send(&mut ws, json!({"type": "ping", "seq": 9})).await;
    let (released, before) = until(&mut ws, "grasp_released", of_type("grasp_released")).await;
    assert!(
        before
            .iter()
            .any(|v| v["type"] == "pong" && v["ref_seq"] == 9),
        "the pong came before the release's answer: {before:?}"
    );
    assert_eq!(released["ref_seq"], 8, "{released}");
    let view = &released["grasp"];
    assert_eq!(view["state"], "done", "{released}");
    for j in ["a", "c"] {
        assert_eq!(state_of(view, j), "released", "{released}");
    }
    assert_eq!(finger(view, "a")["contact"], true);
    assert_eq!(finger(view, "c")["contact"], false);
    limits_restored(&b, view).await;
    // The starter is told it ended (before or after the release's answer).
    let done = match before.iter().find(|v| v["type"] == "grasp_done") {
        Some(done) => done.clone(),
        None => until(&mut ws, "grasp_done", of_type("grasp_done")).await.0,
    };
    assert_eq!(done["grasp"]["id"], id, "{done}");
    assert_eq!(done["grasp"]["state"], "done", "{done}");

    // It ended: releasing again is refused, naming why; stopping answers
    // its final state.
    send(
        &mut ws,
        json!({"type": "grasp_release", "seq": 10, "id": id}),
    )
    .await;
    let (err, _) = until(&mut ws, "an error", of_type("error")).await;
    assert_eq!(err["ref_seq"], 10, "{err}");
    assert_eq!(err["code"], "wrong_state", "{err}");
    assert!(
        err["message"].as_str().is_some_and(|m| m.contains("ended")),
        "{err}"
    );
    send(&mut ws, json!({"type": "grasp_stop", "seq": 11, "id": id})).await;
    let (stopped, _) = until(&mut ws, "grasp_stopped", of_type("grasp_stopped")).await;
    assert_eq!(stopped["ref_seq"], 11, "{stopped}");
    assert_eq!(state_of(&stopped["grasp"], "a"), "released", "{stopped}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_ends_a_grasp_started_over_the_websocket() {
    let b = hand(&[(1, 10.0, 0.05)]).await;
    let mut ws = connect(&b).await;
    // c closes for 2.7 s: the e-stop comes while a holds and c closes.
    send(&mut ws, grasp_msg(1, 80.0)).await;
    let (started, _) = until(&mut ws, "grasp_started", of_type("grasp_started")).await;
    let id = started["grasp"]["id"].as_u64().expect("a grasp id");
    wait_grasp(&b, id, "a holding, c still closing", |v| {
        state_of(v, "a") == "holding" && state_of(v, "c") == "closing"
    })
    .await;
    b.server.post_empty("/api/v1/estop").await.ok();
    let (done, _) = until(&mut ws, "grasp_done", of_type("grasp_done")).await;
    let view = &done["grasp"];
    assert_eq!(view["id"], id, "{done}");
    assert_eq!(view["state"], "done", "{done}");
    for j in ["a", "c"] {
        let f = finger(view, j);
        assert_eq!(f["state"], "aborted", "{done}");
        assert_eq!(f["reason"], "e-stop", "{done}");
    }
    for id in [1, 3] {
        assert!(!b.sim.device(id).expect("device").enabled, "joint {id}");
    }
    limits_restored(&b, view).await;
    // The same over REST.
    let rest = b.server.get(&format!("/api/v1/grasps/{id}")).await;
    assert_eq!(state_of(rest.ok(), "c"), "aborted");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_grasp_messages_are_errors_that_say_what_is_wrong() {
    let b = hand(&[]).await;
    let mut ws = connect(&b).await;
    let cases = [
        (
            json!({"type": "grasp", "seq": 1, "hand": "nope", "speed_dps": 30, "hold_current_a": 0.2}),
            "unknown_device",
            "nope",
        ),
        (
            json!({"type": "grasp", "seq": 2, "hand": "h", "speed_dps": 0, "hold_current_a": 0.2}),
            "out_of_range",
            "speed_dps",
        ),
        (
            json!({"type": "grasp", "seq": 3, "speed_dps": 30, "hold_current_a": 0.2}),
            "bad_message",
            "missing `hand`",
        ),
        (
            json!({"type": "grasp", "seq": 4, "hand": "h", "speed_dps": 30, "hold_a": 0.2}),
            "bad_message",
            "hold_a",
        ),
        (
            json!({"type": "grasp_release", "seq": 5, "id": 99}),
            "unknown_device",
            "no grasp with id 99",
        ),
        (
            json!({"type": "grasp_stop", "seq": 6}),
            "bad_message",
            "missing `id`",
        ),
    ];
    for (msg, code, says) in cases {
        let seq = msg["seq"].clone();
        send(&mut ws, msg).await;
        let (err, before) = until(&mut ws, "an error", of_type("error")).await;
        assert!(
            !before.iter().any(|v| v["type"] == "grasp_started"),
            "{before:?}"
        );
        assert_eq!(err["ref_seq"], seq, "{err}");
        assert_eq!(err["code"], code, "{err}");
        assert!(
            err["message"].as_str().is_some_and(|m| m.contains(says)),
            "{err}"
        );
    }
    // None of them started a grasp.
    b.server.get("/api/v1/grasps/1").await.problem(404);
}
