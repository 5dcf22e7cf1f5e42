//! A WebSocket `move` whose `seq` is no integer is refused with
//! `bad_message` and starts nothing (its answer could not quote the seq).

mod support;

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio_tungstenite::connect_async;
use tokio_tungstenite::tungstenite::Message;

use jointd::protocol::status::fsm;
use support::sim_bus::{self, WAIT};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_with_a_seq_that_is_no_integer_is_a_bad_message_and_starts_nothing() {
    let bus = sim_bus::start(1, None).await;
    bus.server
        .post("/api/v1/buses/sim0/control/enable", json!({"ids": [1]}))
        .await
        .ok();
    bus.wait_fsm(1, fsm::RUN).await;
    let url = format!("{}/api/v1/ws", bus.server.base.replace("http://", "ws://"));
    let (mut ws, _) = connect_async(url).await.expect("connect");
    let mv = json!({"type": "move", "seq": "a",
        "joints": [{"bus": "sim0", "id": 1, "position_deg": 20}], "duration_ms": 200});
    ws.send(Message::text(mv.to_string())).await.expect("send");
    ws.send(Message::text(json!({"type": "ping", "seq": 9}).to_string()))
        .await
        .expect("send");
    // Everything up to the pong: one error, no move_started.
    let mut seen: Vec<Value> = Vec::new();
    let until_pong = async {
        loop {
            let msg = ws.next().await.expect("socket open").expect("message");
            if let Message::Text(t) = msg {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                let pong = v["type"] == "pong";
                seen.push(v);
                if pong {
                    return;
                }
            }
        }
    };
    tokio::time::timeout(WAIT, until_pong)
        .await
        .expect("a pong");
    let errors: Vec<&Value> = seen.iter().filter(|v| v["type"] == "error").collect();
    assert_eq!(errors.len(), 1, "{seen:?}");
    assert_eq!(errors[0]["code"], "bad_message", "{seen:?}");
    assert!(
        errors[0]["message"]
            .as_str()
            .is_some_and(|m| m.contains("`seq`")),
        "{seen:?}"
    );
    assert!(
        !seen.iter().any(|v| v["type"] == "move_started"),
        "{seen:?}"
    );
    let none = bus.server.get("/api/v1/moves/1").await;
    assert_eq!(
        none.status.as_u16(),
        404,
        "no move was started: {}",
        none.body
    );
}
