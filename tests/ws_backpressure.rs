//! A client that stops reading never slows another client or the bus: its
//! writer stalls alone, skipped telemetry is counted, memory stays bounded.
//! The stalled side drives the session through its generic Sink/Stream
//! interface, so "stops reading" is exact rather than a TCP buffer guess.

mod support;

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::Message;
use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio::sync::{mpsc, Semaphore};
use tokio_stream::wrappers::UnboundedReceiverStream;
use tokio_tungstenite::connect_async;

use support::sim_bus::{self, WAIT};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stalled_client_does_not_delay_another() {
    let bus = sim_bus::start(4, None).await;

    // The stalled client: its sink passes a message only when the gate allows.
    let gate = Arc::new(Semaphore::new(3));
    let (delivered_tx, mut delivered) = mpsc::unbounded_channel::<String>();
    let sink_gate = gate.clone();
    let sink = futures_util::sink::unfold(delivered_tx, move |tx, msg: Message| {
        let gate = sink_gate.clone();
        async move {
            if let Ok(permit) = gate.acquire().await {
                permit.forget();
            }
            if let Message::Text(t) = msg {
                let _ = tx.send(t.as_str().to_owned());
            }
            Ok::<_, Infallible>(tx)
        }
    });
    let (incoming_tx, incoming_rx) = mpsc::unbounded_channel::<Result<Message, Infallible>>();
    let state = bus.server_state.clone();
    tokio::spawn(jointd::http::ws::session::run(
        state,
        Box::pin(sink),
        UnboundedReceiverStream::new(incoming_rx),
    ));
    let subscribe = json!({"type":"subscribe","rate_hz":200}).to_string();
    incoming_tx
        .send(Ok(Message::Text(subscribe.into())))
        .expect("send");

    // Let the stalled writer use up its 3 permits (welcome, subscribed, one sample).
    for _ in 0..3 {
        tokio::time::timeout(WAIT, delivered.recv())
            .await
            .expect("first messages")
            .expect("open");
    }

    // The healthy client over a real socket keeps receiving at its rate.
    let url = format!("{}/api/v1/ws", bus.server.base.replace("http://", "ws://"));
    let (mut ws, _) = connect_async(url).await.expect("connect");
    ws.send(tokio_tungstenite::tungstenite::Message::text(
        json!({"type":"subscribe","rate_hz":50}).to_string(),
    ))
    .await
    .expect("send");
    let counters_before = bus.handle.snapshot().counters.clone();
    let mut telemetry = 0;
    let mut healthy_dropped = 0;
    let started = tokio::time::Instant::now();
    while telemetry < 25 {
        let msg = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("healthy client starved")
            .expect("open")
            .expect("message");
        if let tokio_tungstenite::tungstenite::Message::Text(t) = msg {
            let v: Value = serde_json::from_str(t.as_str()).expect("json");
            if v["type"] == "telemetry" {
                telemetry += 1;
                healthy_dropped += v["dropped"].as_u64().unwrap_or(0);
            }
        }
    }
    let elapsed = started.elapsed();
    // 25 messages at 50 Hz: about half a second; the stalled peer must not stretch it.
    assert!(
        elapsed < Duration::from_secs(3),
        "healthy client slowed to {elapsed:?}"
    );
    // A tick delayed past its period by a loaded scheduler counts as one
    // skipped sample; the stalled peer must not cause a run of them.
    assert!(
        healthy_dropped <= 3,
        "the healthy client skipped {healthy_dropped} of 25 samples"
    );
    let counters_after = bus.handle.snapshot().counters.clone();
    assert!(
        counters_after.frames_rx > counters_before.frames_rx,
        "the bus kept polling"
    );

    // Release the stalled client. The first telemetry it gets is the one
    // that was stuck in the sink (built before the stall); the next one
    // carries the count of samples skipped meanwhile.
    gate.add_permits(1000);
    let dropped = async {
        let mut seen = 0;
        let mut dropped = 0;
        while seen < 3 {
            let text = delivered.recv().await.expect("open");
            let v: Value = serde_json::from_str(&text).expect("json");
            if v["type"] == "telemetry" {
                seen += 1;
                dropped += v["dropped"].as_u64().unwrap_or(0);
            }
        }
        dropped
    };
    let dropped = tokio::time::timeout(WAIT, dropped)
        .await
        .expect("telemetry after release");
    // How many depends on how often a loaded host ran the ticker meanwhile;
    // that they are counted and said does not.
    assert!(
        dropped > 0,
        "a client stalled ~0.5 s at 200 Hz was told of no skipped sample"
    );
    assert!(
        bus.server_state
            .ws()
            .dropped_samples
            .load(std::sync::atomic::Ordering::Relaxed)
            >= dropped
    );

    // /metrics lists the skips per connected client: the stalled one has
    // at least what it was told, and its line goes when it does.
    let (stalled, count) = client_drops(&bus)
        .await
        .into_iter()
        .max_by_key(|(_, n)| *n)
        .expect("a line per connected client");
    assert!(count >= dropped, "client {stalled}: {count} < {dropped}");
    drop(incoming_tx);
    let gone = async {
        while client_drops(&bus).await.iter().any(|(c, _)| *c == stalled) {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    };
    tokio::time::timeout(WAIT, gone)
        .await
        .expect("the stalled client's line goes with its connection");
}

/// (client, skipped samples) from `jointd_ws_client_dropped_samples_total`.
async fn client_drops(bus: &sim_bus::SimBus) -> Vec<(String, u64)> {
    let metrics = bus.server.get("/metrics").await;
    let text = metrics.body.as_str().expect("text").to_owned();
    text.lines()
        .filter_map(|l| l.strip_prefix("jointd_ws_client_dropped_samples_total{client=\""))
        .filter_map(|l| {
            let (client, rest) = l.split_once("\"} ")?;
            Some((client.to_owned(), rest.trim().parse::<f64>().ok()? as u64))
        })
        .collect()
}

/// A client that takes nothing for 8 s is closed with 1008 "too slow",
/// counted in /metrics, and the replies it never got are counted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_takes_nothing_is_closed_too_slow_and_counted() {
    use axum::extract::ws::close_code;
    let bus = sim_bus::start(1, None).await;
    // Takes the welcome, then holds the next text for 8.5 s: past the 8 s
    // slow-client limit, within the 1 s the close frame then has to go out
    // (a sink takes nothing else while a message is stuck in it).
    let (delivered_tx, mut delivered) = mpsc::unbounded_channel::<Message>();
    let taken = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let sink = futures_util::sink::unfold(delivered_tx, move |tx, msg: Message| {
        let taken = taken.clone();
        async move {
            let text = matches!(msg, Message::Text(_));
            if text && taken.fetch_add(1, std::sync::atomic::Ordering::Relaxed) >= 1 {
                tokio::time::sleep(Duration::from_millis(8500)).await;
            }
            let _ = tx.send(msg);
            Ok::<_, Infallible>(tx)
        }
    });
    let (incoming_tx, incoming_rx) = mpsc::unbounded_channel::<Result<Message, Infallible>>();
    let state = bus.server_state.clone();
    let session = tokio::spawn(jointd::http::ws::session::run(
        state,
        Box::pin(sink),
        UnboundedReceiverStream::new(incoming_rx),
    ));
    let welcome = tokio::time::timeout(WAIT, delivered.recv())
        .await
        .expect("welcome");
    assert!(matches!(welcome, Some(Message::Text(_))));
    let ws = bus.server_state.ws();
    let load = |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed);
    let (slow_before, unsent_before) = (load(&ws.slow_disconnects), load(&ws.unsent_replies));
    // Telemetry stalls the writer; two pings wait behind it, never to be sent.
    for m in [
        json!({"type":"subscribe","rate_hz":100}),
        json!({"type":"ping","seq":1}),
        json!({"type":"ping","seq":2}),
    ] {
        incoming_tx
            .send(Ok(Message::Text(m.to_string().into())))
            .expect("send");
    }
    let close = async {
        loop {
            match delivered.recv().await {
                Some(Message::Text(_)) => continue,
                other => return other,
            }
        }
    };
    let close = tokio::time::timeout(Duration::from_secs(20), close)
        .await
        .expect("closed within the slow-client timeout");
    let Some(Message::Close(Some(frame))) = close else {
        panic!("expected a close frame, got {close:?}");
    };
    assert_eq!(frame.code, close_code::POLICY);
    assert!(
        frame.reason.as_str().starts_with("too slow"),
        "{}",
        frame.reason
    );
    // The reader ends with the writer, though the client never closed.
    tokio::time::timeout(WAIT, session)
        .await
        .expect("session ended")
        .expect("no panic");
    assert_eq!(load(&ws.slow_disconnects), slow_before + 1);
    assert!(
        load(&ws.unsent_replies) > unsent_before,
        "the pings queued behind the stall are counted"
    );
    let metrics = bus.server.get("/metrics").await;
    let text = metrics.body.as_str().expect("text").to_owned();
    assert!(
        text.contains("\njointd_ws_slow_disconnects_total "),
        "{text}"
    );
    drop(incoming_tx);
}

/// A client whose reply queue is full still hears that its stream ended:
/// the `stream_ended` is held, in order, until it takes its replies again;
/// the other replies beyond the queue are dropped and counted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_end_reaches_a_client_whose_reply_queue_was_full() {
    let bus = sim_bus::start(1, None).await;
    bus.enable_running(1).await;
    // Passes what it is given while open; closed, it takes nothing, and
    // says when a message waits in it.
    let (open, open_rx) = tokio::sync::watch::channel(true);
    let waiting = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (delivered_tx, mut delivered) = mpsc::unbounded_channel::<Value>();
    let sink_waiting = waiting.clone();
    let sink = futures_util::sink::unfold(delivered_tx, move |tx, msg: Message| {
        let mut open = open_rx.clone();
        let waiting = sink_waiting.clone();
        async move {
            if !*open.borrow() {
                waiting.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            let _ = open.wait_for(|o| *o).await;
            if let Message::Text(t) = msg {
                let _ = tx.send(serde_json::from_str(t.as_str()).expect("JSON"));
            }
            Ok::<_, Infallible>(tx)
        }
    });
    let (incoming_tx, incoming_rx) = mpsc::unbounded_channel::<Result<Message, Infallible>>();
    tokio::spawn(jointd::http::ws::session::run(
        bus.server_state.clone(),
        Box::pin(sink),
        UnboundedReceiverStream::new(incoming_rx),
    ));
    let send = |m: Value| {
        incoming_tx
            .send(Ok(Message::Text(m.to_string().into())))
            .expect("send");
    };
    let target = |seq: u64| {
        json!({"type": "setpoints", "seq": seq,
               "targets": [{"bus": "sim0", "id": 1, "position_deg": 5.0}]})
    };
    assert_eq!(next(&mut delivered).await["type"], "welcome");
    // A stream to joint 1, live once the ping behind it is answered.
    send(target(1));
    send(json!({"type": "ping", "seq": 2}));
    loop {
        let m = next(&mut delivered).await;
        assert_ne!(m["type"], "error", "target 1 refused: {m}");
        if m["type"] == "pong" {
            assert_eq!(m["ref_seq"], 2, "{m}");
            break;
        }
    }

    // The sink now takes nothing: a first ping's pong waits in it (the
    // writer stuck), then 100 pings fill the queue, and the rest are dropped.
    open.send_replace(false);
    send(json!({"type": "ping", "seq": 99}));
    wait_for("the writer stuck in the sink", || {
        waiting.load(std::sync::atomic::Ordering::Relaxed)
    })
    .await;
    let dropped = || {
        bus.server_state
            .ws()
            .dropped_replies
            .load(std::sync::atomic::Ordering::Relaxed)
    };
    let before = dropped();
    for seq in 100..200 {
        send(json!({"type": "ping", "seq": seq}));
    }
    wait_for("pings dropped from the full queue", || dropped() > before).await;
    // The stream ends while the queue is full; the next target for it is
    // refused (that refusal dropped, as a reply beyond the queue is).
    bus.handle.estop().await.expect("e-stop");
    let before = dropped();
    send(target(3));
    wait_for("the refusal of target 3 dropped", || dropped() > before).await;

    open.send_replace(true);
    // The queued pongs, then the stream's end (to old code, never).
    let mut pongs = Vec::new();
    let ended = loop {
        let m = tokio::time::timeout(WAIT, delivered.recv())
            .await
            .unwrap_or_else(|_| panic!("no stream_ended after the pongs {pongs:?}"))
            .expect("open");
        match m["type"].as_str() {
            Some("pong") => pongs.push(m["ref_seq"].as_u64().expect("a seq")),
            Some("stream_ended") => break m,
            _ => {}
        }
    };
    assert_eq!(
        (ended["id"].as_u64(), ended["reason"].as_str()),
        (Some(1), Some("estopped")),
        "{ended}"
    );
    // Before it, in order and none missing, the pongs the sink and the
    // queue held (64 or 65: an event may have been the message stuck in
    // the sink); the rest were dropped.
    let held_pongs = pongs.len() as u64;
    assert!(
        (64..=65).contains(&held_pongs) && pongs == (99..99 + held_pongs).collect::<Vec<_>>(),
        "the pongs before it: {pongs:?}"
    );
    // Once taken, nothing more is held: the next ping is answered, and the
    // end is not told twice.
    send(json!({"type": "ping", "seq": 4}));
    loop {
        let m = next(&mut delivered).await;
        assert_ne!(m["type"], "stream_ended", "told twice: {m}");
        if m["type"] == "pong" && m["ref_seq"] == 4 {
            break;
        }
    }
    drop(incoming_tx);
}

/// The next message the sink passed.
async fn next(delivered: &mut mpsc::UnboundedReceiver<Value>) -> Value {
    tokio::time::timeout(WAIT, delivered.recv())
        .await
        .expect("a message")
        .expect("open")
}

/// Waits (polling) until `done` holds.
async fn wait_for(what: &str, done: impl Fn() -> bool) {
    let waited = tokio::time::timeout(WAIT, async {
        while !done() {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
    .await;
    assert!(waited.is_ok(), "timed out waiting for {what}");
}
