//! Acks over the WebSocket when the bus is faster than the session: a batch
//! whose frame reached the wire before the writer heard of the batch is
//! acknowledged at once, not on the bus's next write (which may never come:
//! a client that waits for each ack sends nothing more).

mod support;

use std::convert::Infallible;
use std::time::{Duration, Instant};

use axum::extract::ws::Message;
use serde_json::{json, Value};
use tokio::sync::mpsc;
use tokio_stream::wrappers::UnboundedReceiverStream;

use jointd::bus::handle::WireAck;
use support::fake_bus::FakeBus;

#[tokio::test]
async fn a_batch_already_on_the_wire_is_acked_without_another_write() {
    let bus = FakeBus::new("fake", &[1]);
    let state = jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            Default::default(),
        )),
        None,
    );
    let server = support::http::serve(state.clone()).await;
    server
        .post_empty("/api/v1/buses/fake/devices/1/enable")
        .await
        .ok();

    // The wire is already past any sequence number this batch can get, and
    // nothing writes to it afterwards.
    bus.handle.shared().wire_acks.send_replace(WireAck {
        seq: 1_000_000,
        at: Some(Instant::now()),
    });

    let (out_tx, mut out) = mpsc::unbounded_channel::<String>();
    let sink = futures_util::sink::unfold(out_tx, |tx, msg: Message| async move {
        if let Message::Text(t) = msg {
            let _ = tx.send(t.as_str().to_owned());
        }
        Ok::<_, Infallible>(tx)
    });
    let (in_tx, in_rx) = mpsc::unbounded_channel::<Result<Message, Infallible>>();
    tokio::spawn(jointd::http::ws::session::run(
        state,
        Box::pin(sink),
        UnboundedReceiverStream::new(in_rx),
    ));
    // The writer is up (its welcome is out) and, given a moment, has taken
    // the wire's position and gone idle: the order the race needs.
    let welcome = tokio::time::timeout(Duration::from_secs(5), out.recv())
        .await
        .expect("welcome")
        .expect("session open");
    assert!(welcome.contains("\"welcome\""), "{welcome}");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let batch = json!({"type":"setpoints","seq":7,"ack":true,"targets":[{"bus":"fake","id":1,"position_deg":5}]});
    in_tx
        .send(Ok(Message::Text(batch.to_string().into())))
        .expect("session open");

    // Well under the writer's 1 s ack timeout, after which it would answer
    // with an error instead.
    let deadline = tokio::time::Instant::now() + Duration::from_millis(700);
    loop {
        let text = tokio::time::timeout_at(deadline, out.recv())
            .await
            .expect("no ack within 700 ms")
            .expect("session open");
        let v: Value = serde_json::from_str(&text).expect("json");
        match v["type"].as_str() {
            Some("ack") => {
                assert_eq!(v["ref_seq"], 7);
                break;
            }
            Some("error") => panic!("error instead of an ack: {v}"),
            _ => {}
        }
    }
}
