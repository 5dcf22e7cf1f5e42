//! The WebSocket endpoint over a real socket (tokio-tungstenite) against the
//! bus engine and the simulator: subscribe and telemetry, batch setpoints
//! moving joints, acks, every error, the watchdog's two policies, auth, and
//! a stalled client not delaying another.

mod support;

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{connect_async, MaybeTlsStream, WebSocketStream};

use jointd::protocol::status::fsm;
use support::sim_bus::{self, SimBus, WAIT};

struct Client {
    ws: WebSocketStream<MaybeTlsStream<TcpStream>>,
}

async fn connect_with(
    url: String,
    bearer: Option<&str>,
) -> Result<Client, tokio_tungstenite::tungstenite::Error> {
    let mut req = url.into_client_request()?;
    if let Some(t) = bearer {
        req.headers_mut().insert(
            "Authorization",
            format!("Bearer {t}").parse().expect("header"),
        );
    }
    let (ws, _) = connect_async(req).await?;
    Ok(Client { ws })
}

fn ws_url(bus: &SimBus) -> String {
    format!("{}/api/v1/ws", bus.server.base.replace("http://", "ws://"))
}

async fn connect(bus: &SimBus) -> Client {
    let mut c = connect_with(ws_url(bus), None).await.expect("connect");
    let w = c.next_of("welcome").await;
    assert_eq!(w["protocol"], "jointd.ws.v1");
    c
}

impl Client {
    async fn send(&mut self, v: Value) {
        self.ws
            .send(Message::text(v.to_string()))
            .await
            .expect("send");
    }

    async fn send_text(&mut self, t: &str) {
        self.ws
            .send(Message::text(t.to_owned()))
            .await
            .expect("send");
    }

    /// The close frame the server ends the session with (other messages skipped).
    async fn close_frame(&mut self) -> tokio_tungstenite::tungstenite::protocol::frame::CloseFrame {
        let close = async {
            loop {
                match self.ws.next().await {
                    Some(Ok(Message::Close(frame))) => return frame,
                    Some(Ok(_)) => continue,
                    other => panic!("no close frame: {other:?}"),
                }
            }
        };
        tokio::time::timeout(WAIT, close)
            .await
            .expect("close in time")
            .expect("a close frame with a code")
    }

    /// The next message of type `kind`, skipping others (telemetry, events).
    async fn next_of(&mut self, kind: &str) -> Value {
        let wait = async {
            loop {
                let msg = self.ws.next().await.expect("socket open").expect("message");
                if let Message::Text(t) = msg {
                    let v: Value = serde_json::from_str(t.as_str()).expect("server sends JSON");
                    if v["type"] == kind {
                        return v;
                    }
                }
            }
        };
        tokio::time::timeout(WAIT, wait)
            .await
            .unwrap_or_else(|_| panic!("no `{kind}` message"))
    }

    /// The next event but the audit's (`command`: who sent what, which
    /// every REST and WebSocket command of a test makes).
    async fn next_event(&mut self) -> Value {
        loop {
            let e = self.next_of("event").await;
            if e["event"]["event"] != "command" {
                return e;
            }
        }
    }

    /// Sends a message expected to be rejected; returns the error.
    async fn rejected(&mut self, msg: Value) -> Value {
        self.send(msg).await;
        self.next_of("error").await
    }
}

async fn enable(bus: &SimBus, ids: &[u8]) {
    bus.server
        .post("/api/v1/buses/sim0/control/enable", json!({"ids": ids}))
        .await
        .ok();
    for &id in ids {
        bus.wait_fsm(id, fsm::RUN).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn telemetry_subscription_content_and_rate() {
    let bus = sim_bus::start(4, None).await;
    let mut c = connect(&bus).await;
    c.send(json!({"type":"subscribe","seq":7,"devices":[1,3],"fields":["angle_deg","state"],"rate_hz":20})).await;
    let sub = c.next_of("subscribed").await;
    assert_eq!(
        (sub["ref_seq"].as_u64(), sub["rate_hz"].as_f64()),
        (Some(7), Some(20.0))
    );
    let first = c.next_of("telemetry").await;
    let started = tokio::time::Instant::now();
    let joints = first["joints"].as_array().expect("joints");
    assert_eq!(
        joints
            .iter()
            .map(|j| j["id"].as_u64().unwrap_or(0))
            .collect::<Vec<_>>(),
        vec![1, 3]
    );
    for j in joints {
        assert_eq!(j["bus"], "sim0");
        assert_eq!(j["online"], true);
        assert!(j["angle_deg"].is_number() && j["state"] == "ready", "{j}");
        assert!(j["age_ms"].as_f64().is_some_and(|a| a >= 0.0));
        assert!(
            j.get("q_current_a").is_none(),
            "unsubscribed field sent: {j}"
        );
    }
    let mut last = first["seq"].as_u64().expect("seq");
    for _ in 0..10 {
        let t = c.next_of("telemetry").await;
        let seq = t["seq"].as_u64().expect("seq");
        assert_eq!(seq, last + 1, "telemetry seq is monotonic");
        last = seq;
    }
    // 10 messages at 20 Hz take about 0.5 s; far less means the rate is not applied.
    assert!(
        started.elapsed() >= Duration::from_millis(350),
        "{:?}",
        started.elapsed()
    );
    c.send(json!({"type":"unsubscribe","seq":8})).await;
    assert_eq!(c.next_of("unsubscribed").await["ref_seq"], 8);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batch_setpoints_move_joints_and_are_acknowledged() {
    let bus = sim_bus::start(4, None).await;
    enable(&bus, &[1, 3, 4]).await;
    let mut c = connect(&bus).await;
    c.send(json!({"type":"setpoints","seq":41,"ack":true,"targets":[
        {"id":1,"position_deg":20.0,"speed_dps":200},
        {"bus":"sim0","id":3,"position_deg":-15.0,"speed_dps":200},
        {"id":4,"position_deg":10.0}]}))
        .await;
    let ack = c.next_of("ack").await;
    assert_eq!(
        (ack["ref_seq"].as_u64(), ack["joints"].as_u64()),
        (Some(41), Some(3))
    );
    assert!(ack["latency_us"].is_u64());
    for (id, deg) in [(1u8, 20.0), (3, -15.0), (4, 10.0)] {
        let reached = async {
            loop {
                if bus
                    .sim
                    .device(id)
                    .is_some_and(|d| (d.angle_deg - deg).abs() < 0.5)
                {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        };
        tokio::time::timeout(WAIT, reached)
            .await
            .unwrap_or_else(|_| panic!("joint {id} did not reach {deg}°"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_error_is_reported_and_nothing_partial_is_applied() {
    let bus = sim_bus::start(4, None).await;
    enable(&bus, &[1, 2, 3]).await;
    let mut c = connect(&bus).await;
    let cases: Vec<(Value, &str)> = vec![
        (json!({"type":"dance","seq":1}), "bad_message"),
        (
            json!({"type":"setpoints","seq":2,"targets":[{"id":1,"pos":3}]}),
            "bad_message",
        ),
        (
            json!({"type":"setpoints","seq":3,"targets":[]}),
            "bad_message",
        ),
        (
            json!({"type":"setpoints","seq":4,"targets":[{"bus":"nope","id":1,"position_deg":1}]}),
            "unknown_bus",
        ),
        (
            json!({"type":"setpoints","seq":5,"targets":[{"id":40,"position_deg":1}]}),
            "unknown_device",
        ),
        (
            json!({"type":"setpoints","seq":6,"targets":[{"id":1,"position_deg":300}]}),
            "out_of_range",
        ),
        (
            json!({"type":"setpoints","seq":7,"targets":[{"id":200,"position_deg":1}]}),
            "out_of_range",
        ),
        (
            json!({"type":"setpoints","seq":8,"targets":[{"id":2,"position_deg":60}]}),
            "out_of_limit",
        ),
        (
            json!({"type":"setpoints","seq":9,"targets":[{"id":4,"position_deg":5}]}),
            "wrong_state",
        ),
        (
            json!({"type":"setpoints","seq":10,"targets":[{"id":1,"position_deg":5},{"id":1,"position_deg":6}]}),
            "bad_message",
        ),
        (
            json!({"type":"setpoints","seq":11,"targets":(0..300).map(|_| json!({"id":1,"position_deg":1})).collect::<Vec<_>>()}),
            "too_many",
        ),
        (
            json!({"type":"subscribe","seq":12,"rate_hz":5000}),
            "out_of_range",
        ),
        (
            json!({"type":"subscribe","seq":13,"buses":["nope"]}),
            "unknown_bus",
        ),
        (
            json!({"type":"watchdog","seq":14,"hold_timeout_ms":5}),
            "out_of_range",
        ),
    ];
    for (msg, code) in cases {
        let seq = msg["seq"].clone();
        let e = c.rejected(msg).await;
        assert_eq!(
            (e["code"].as_str(), &e["ref_seq"]),
            (Some(code), &seq),
            "{e}"
        );
        assert!(e["message"].as_str().is_some_and(|m| !m.is_empty()));
    }
    c.send_text("{not json").await;
    assert_eq!(c.next_of("error").await["code"], "bad_json");

    // One bad target in a batch: the good one is not applied either.
    let before = bus.handle.shared().setpoints.get(1);
    let e = c
        .rejected(json!({"type":"setpoints","seq":20,"targets":[
        {"id":1,"position_deg":10},{"id":2,"position_deg":60}]}))
        .await;
    assert_eq!(
        (e["code"].as_str(), e["field"].as_str()),
        (Some("out_of_limit"), Some("targets[1].position_deg"))
    );
    assert_eq!(
        bus.handle.shared().setpoints.get(1),
        before,
        "nothing of a rejected batch is applied"
    );

    // The connection is still usable.
    c.send(json!({"type":"ping","seq":99})).await;
    assert_eq!(c.next_of("pong").await["ref_seq"], 99);
}

/// The server offers its codec a few KiB per read of the socket; a
/// message many reads long still arrives whole, and one over the size
/// limit is refused without taking the daemon down.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_message_longer_than_one_read_arrives_whole() {
    let bus = sim_bus::start(1, None).await;
    let mut c = connect(&bus).await;
    // 100 kB of whitespace inside a ping: valid JSON, a dozen reads long.
    let padded = format!(r#"{{"type":"ping",{}"seq":41}}"#, " ".repeat(100_000));
    c.send_text(&padded).await;
    assert_eq!(c.next_of("pong").await["ref_seq"], 41);
    c.send(json!({"type":"ping","seq":42})).await;
    assert_eq!(c.next_of("pong").await["ref_seq"], 42);

    // Over the 256 KiB limit: this connection ends, the daemon serves on.
    let huge = format!(r#"{{"type":"ping",{}"seq":43}}"#, " ".repeat(300_000));
    let _ = c.ws.send(Message::text(huge)).await;
    let ended = tokio::time::timeout(WAIT, async {
        loop {
            match c.ws.next().await {
                Some(Ok(Message::Text(t))) if t.as_str().contains("\"pong\"") => return false,
                Some(Ok(Message::Close(_))) | Some(Err(_)) | None => return true,
                Some(Ok(_)) => continue,
            }
        }
    })
    .await
    .expect("the oversized message is answered by the end of the connection");
    assert!(ended, "an oversized message was answered");
    let mut again = connect(&bus).await;
    again.send(json!({"type":"ping","seq":44})).await;
    assert_eq!(again.next_of("pong").await["ref_seq"], 44);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchdog_hold_freezes_joints_and_tells_everyone() {
    let bus = sim_bus::start(4, None).await;
    enable(&bus, &[1, 2]).await;
    let mut observer = connect(&bus).await;
    let mut teleop = connect(&bus).await;
    teleop
        .send(json!({"type":"watchdog","seq":1,"hold_timeout_ms":150,"policy":"hold"}))
        .await;
    assert_eq!(teleop.next_of("watchdog_set").await["policy"], "hold");
    // Stream towards far targets, then stop streaming mid-move.
    teleop.send(json!({"type":"setpoints","targets":[{"id":1,"position_deg":200,"speed_dps":30},{"id":2,"position_deg":40,"speed_dps":30}]})).await;
    let event = observer.next_event().await;
    assert_eq!(
        (
            event["event"]["event"].as_str(),
            event["event"]["policy"].as_str(),
            event["event"]["why"].as_str()
        ),
        (Some("watchdog"), Some("hold"), Some("timeout"))
    );
    assert_eq!(event["event"]["joints"].as_array().map(Vec::len), Some(2));
    // Held: joint 1 keeps running, and its target is no longer 200°.
    let held = bus.handle.shared().setpoints.get(1).expect("a hold target");
    assert!(
        f64::from(held.setpoint.pos_ref) / 128.0 < 150.0,
        "target still far: {held:?}"
    );
    assert_eq!(bus.sim.device(1).map(|d| d.fsm), Some(fsm::RUN));
}

/// Held in speed mode, a joint stops: its speed slot is the motion itself,
/// so the hold sends 0, not the last speed streamed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchdog_hold_stops_a_joint_in_speed_mode() {
    let bus = sim_bus::start(4, None).await;
    enable(&bus, &[1]).await;
    let moded = bus
        .server
        .put("/api/v1/buses/sim0/devices/1/mode", json!({"mode":"speed"}))
        .await;
    assert_eq!(moded.status, 200, "{:?}", moded.body);
    let mut teleop = connect(&bus).await;
    teleop
        .send(json!({"type":"watchdog","seq":1,"hold_timeout_ms":150,"policy":"hold"}))
        .await;
    teleop.next_of("watchdog_set").await;
    teleop
        .send(json!({"type":"setpoints","seq":2,"ack":true,"targets":[{"id":1,"speed_dps":30}]}))
        .await;
    teleop.next_of("ack").await;
    let spinning = |want: bool| {
        bus.sim
            .device(1)
            .is_some_and(|d| (d.spd_ref != 0) == want && d.fsm == fsm::RUN)
    };
    let deadline = tokio::time::Instant::now() + WAIT;
    while !spinning(true) {
        assert!(tokio::time::Instant::now() < deadline, "joint 1 never spun");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    // The stream stops: the watchdog holds the joint, at speed 0.
    let event = teleop.next_event().await;
    assert_eq!(event["event"]["event"], "watchdog");
    while !spinning(false) {
        assert!(
            tokio::time::Instant::now() < deadline,
            "joint 1 still spinning after the hold: {:?}",
            bus.sim.device(1).map(|d| d.spd_ref)
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let held = bus.handle.shared().setpoints.get(1).expect("a hold target");
    assert_eq!(held.setpoint.spd_ref, 0);
}

/// An observer, and a client that armed its watchdog with `policy` and
/// `hold_ms` and had a target for joint 3 acknowledged.
async fn observer_and_watched_teleop(bus: &SimBus, hold_ms: u64, policy: &str) -> (Client, Client) {
    enable(bus, &[3]).await;
    let observer = connect(bus).await;
    let mut teleop = connect(bus).await;
    teleop
        .send(json!({"type":"watchdog","hold_timeout_ms":hold_ms,"policy":policy}))
        .await;
    teleop.next_of("watchdog_set").await;
    teleop
        .send(json!({"type":"setpoints","seq":5,"ack":true,"targets":[{"id":3,"position_deg":5}]}))
        .await;
    teleop.next_of("ack").await;
    (observer, teleop)
}

/// A watchdog event's kind, policy and cause.
fn fired(event: &Value) -> (Option<&str>, Option<&str>, Option<&str>) {
    let e = &event["event"];
    (e["event"].as_str(), e["policy"].as_str(), e["why"].as_str())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchdog_disable_applies_when_the_socket_closes() {
    let bus = sim_bus::start(4, None).await;
    let (mut observer, teleop) = observer_and_watched_teleop(&bus, 5000, "disable").await;
    drop(teleop); // the network goes away: no close handshake
    let event = observer.next_event().await;
    assert_eq!(
        fired(&event),
        (Some("watchdog"), Some("disable"), Some("closed"))
    );
    bus.wait_fsm(3, fsm::READY).await;
}

/// A client held back past its hold timeout, then gone: the timeout holds the
/// joint, and the close applies the policy again, so every client hears the
/// close even after a timeout.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watchdog_fired_on_a_timeout_fires_again_when_the_socket_closes() {
    let bus = sim_bus::start(4, None).await;
    let (mut observer, teleop) = observer_and_watched_teleop(&bus, 100, "hold").await;
    let event = observer.next_event().await;
    assert_eq!(
        fired(&event),
        (Some("watchdog"), Some("hold"), Some("timeout")),
        "{event}"
    );
    drop(teleop);
    let event = observer.next_event().await;
    assert_eq!(
        fired(&event),
        (Some("watchdog"), Some("hold"), Some("closed")),
        "{event}"
    );
    assert_eq!(event["event"]["joints"], json!([{"bus":"sim0","id":3}]));
    assert_eq!(bus.sim.device(3).map(|d| d.fsm), Some(fsm::RUN));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn auth_applies_to_the_websocket() {
    let bus = sim_bus::start(2, Some("s3cret")).await;
    let url = ws_url(&bus);
    assert!(
        connect_with(url.clone(), None).await.is_err(),
        "no token must be refused"
    );
    assert!(
        connect_with(url.clone(), Some("wrong")).await.is_err(),
        "a wrong token must be refused"
    );
    let mut by_header = connect_with(url.clone(), Some("s3cret"))
        .await
        .expect("bearer header");
    by_header.next_of("welcome").await;
    let mut by_query = connect_with(format!("{url}?token=s3cret"), None)
        .await
        .expect("?token=");
    by_query.next_of("welcome").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn config_default_watchdog_and_joint_names() {
    use jointd::control::teleop::{WatchdogDefault, WatchdogPolicy};
    use jointd::control::Options;
    let bus = sim_bus::start(2, None).await;
    let mut options = Options::default();
    options
        .joint_names
        .insert((Some("sim0".into()), 1), "index_mcp".into());
    options.watchdog = WatchdogDefault {
        hold_timeout_ms: 100,
        policy: WatchdogPolicy::Disable,
    };
    assert!(bus.server_state.control().set_options(options).is_ok());
    enable(&bus, &[1]).await;
    let mut observer = connect(&bus).await;
    observer
        .send(json!({"type":"subscribe","devices":[1],"fields":["angle_deg"],"rate_hz":20}))
        .await;
    let t = observer.next_of("telemetry").await;
    assert_eq!(t["joints"][0]["name"], "index_mcp");
    let mut teleop = connect(&bus).await;
    // No `watchdog` message: the config's default arms on the first batch.
    teleop
        .send(json!({"type":"setpoints","targets":[{"id":1,"position_deg":3}]}))
        .await;
    let event = observer.next_event().await;
    assert_eq!(
        (
            event["event"]["policy"].as_str(),
            event["event"]["why"].as_str()
        ),
        (Some("disable"), Some("timeout"))
    );
    bus.wait_fsm(1, fsm::READY).await;
    drop(teleop);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_cut_is_an_event_a_disabled_reason_and_a_metric() {
    let bus = sim_bus::start(2, None).await;
    enable(&bus, &[2]).await;
    let mut observer = connect(&bus).await;
    observer
        .send(json!({"type":"subscribe","devices":[2],"fields":["state"],"rate_hz":50}))
        .await;
    observer.next_of("subscribed").await;
    bus.sim.inject(jointd::sim::Fault::PowerCycle { dev_id: 2 });
    // A long boot may take it offline and back first.
    let event = loop {
        let e = observer.next_event().await;
        if !matches!(
            e["event"]["event"].as_str(),
            Some("device_offline" | "device_online")
        ) {
            break e;
        }
    };
    assert_eq!(event["event"]["event"], "device_reset", "{event}");
    assert_eq!(event["event"]["id"], 2);
    assert_eq!(event["event"]["state_before"], "run");
    bus.wait_snapshot("reset shown", |s| s.devices[&2].resets == 1)
        .await;
    // Telemetry sent before the reset may still be on its way: the first
    // one built from a snapshot after it says why the joint is disabled.
    loop {
        let t = observer.next_of("telemetry").await;
        if t["joints"][0]["state"] == "ready" {
            assert_eq!(t["joints"][0]["disabled_reason"], "reset", "{t}");
            break;
        }
    }
    let dev = bus.server.get("/api/v1/buses/sim0/devices/2").await;
    let dev = dev.ok();
    assert_eq!(
        (
            &dev["disabled_reason"],
            &dev["resets"],
            &dev["status"]["state"]
        ),
        (&json!("reset"), &json!(1), &json!("ready")),
        "{dev}"
    );
    assert!(dev["last_reset"]["seen"].is_string(), "{dev}");
    let metrics = bus.server.get("/metrics").await;
    let text = metrics.body.as_str().expect("text").to_owned();
    assert!(
        text.contains("jointd_device_resets_total{bus=\"sim0\",id=\"2\"} 1"),
        "{text}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_watchdog_disable_then_enable_does_not_move_the_joint() {
    let bus = sim_bus::start(4, None).await;
    enable(&bus, &[3]).await;
    let mut teleop = connect(&bus).await;
    teleop
        .send(json!({"type":"watchdog","hold_timeout_ms":100,"policy":"disable"}))
        .await;
    teleop.next_of("watchdog_set").await;
    // Slowly (~32 °/s at the output) towards 100°, then the stream stops.
    teleop.send(json!({"type":"setpoints","seq":5,"ack":true,"targets":[{"id":3,"position_deg":100,"speed_dps":30}]})).await;
    teleop.next_of("ack").await;
    bus.wait_fsm(3, fsm::READY).await;
    let rest = tokio::time::Instant::now();
    loop {
        let d = bus.sim.device(3).expect("device 3");
        if d.velocity_deg_s.abs() < 0.1 {
            break;
        }
        assert!(rest.elapsed() < WAIT, "joint 3 never came to rest");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let stood = bus.sim.device(3).unwrap().angle_deg;
    assert!(stood > 0.5, "it had started moving: {stood}°");
    enable(&bus, &[3]).await;
    let start = tokio::time::Instant::now();
    while start.elapsed() < Duration::from_millis(300) {
        let now = bus.sim.device(3).unwrap().angle_deg;
        assert!(
            (now - stood).abs() < 0.5,
            "joint 3 moved from {stood:.2}° to {now:.2}° after the enable"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_type_that_is_not_a_string_is_named_as_such() {
    let bus = sim_bus::start(1, None).await;
    let mut c = connect(&bus).await;
    let e = c.rejected(json!({"type": 5, "seq": 7})).await;
    assert_eq!(e["code"], "bad_message");
    assert_eq!(e["ref_seq"], 7);
    let msg = e["message"].as_str().expect("message");
    assert!(msg.contains("`type` must be a string"), "{msg}");
    assert!(!msg.contains("missing"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daemon_shutdown_closes_every_session_with_going_away() {
    use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
    let bus = sim_bus::start(1, None).await;
    let mut c = connect(&bus).await;
    c.send(json!({"type":"subscribe","rate_hz":50})).await;
    c.next_of("telemetry").await;
    bus.server_state.ws().shut_down();
    let frame = c.close_frame().await;
    assert_eq!(frame.code, CloseCode::Away);
    assert!(frame.reason.contains("shutting down"), "{}", frame.reason);
    // A connection made after shutdown is closed at once too.
    let mut late = connect_with(ws_url(&bus), None).await.expect("connect");
    let first_close = async {
        while let Some(Ok(m)) = late.ws.next().await {
            if let Message::Close(f) = m {
                return f;
            }
        }
        None
    };
    let f = tokio::time::timeout(WAIT, first_close)
        .await
        .expect("closed");
    assert_eq!(f.expect("code").code, CloseCode::Away);
    let metrics = bus.server.get("/metrics").await;
    let text = metrics.body.as_str().expect("text").to_owned();
    for family in [
        "jointd_ws_connections",
        "jointd_ws_dropped_samples_total",
        "jointd_ws_unsent_replies_total",
        "jointd_ws_slow_disconnects_total",
    ] {
        assert!(text.contains(&format!("\n{family} ")), "{family} in {text}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversized_message_ends_the_session_with_a_policy_close() {
    use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
    let bus = sim_bus::start(1, None).await;
    let mut c = connect(&bus).await;
    // Over the endpoint's 256 KiB message limit: a JSON string nobody parses.
    let big = format!(
        "{{\"type\":\"subscribe\",\"pad\":\"{}\"}}",
        "x".repeat(300 * 1024)
    );
    // The server may close while the frame is still going out.
    let _ = c.ws.send(Message::text(big)).await;
    let frame = c.close_frame().await;
    assert_eq!(frame.code, CloseCode::Policy);
    assert!(frame.reason.contains("message refused"), "{}", frame.reason);
    assert!(frame.reason.len() <= 123);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_message_starts_a_move_and_its_events_follow() {
    let bus = sim_bus::start(2, None).await;
    enable(&bus, &[1, 2]).await;
    let mut c = connect(&bus).await;
    // Outside joint 2's soft limit (±45°): refused whole, nothing starts.
    let e = c
        .rejected(json!({"type": "move", "seq": 4,
            "joints": [{"bus": "sim0", "id": 1, "position_deg": 10},
                       {"bus": "sim0", "id": 2, "position_deg": 90}],
            "duration_ms": 300}))
        .await;
    assert_eq!(e["ref_seq"], 4);
    assert_eq!(e["code"], "out_of_limit");
    assert_eq!(e["field"], "joints[1].position_deg");
    // An unknown field is named, like every other message's.
    let e = c
        .rejected(json!({"type": "move", "seq": 5, "joints": [], "speed": 3}))
        .await;
    assert_eq!(e["code"], "bad_message");
    assert!(
        e["message"].as_str().is_some_and(|m| m.contains("speed")),
        "{e}"
    );
    c.send(json!({"type": "move", "seq": 6,
        "joints": [{"bus": "sim0", "id": 1, "position_deg": 10},
                   {"bus": "sim0", "id": 2, "position_deg": -10}],
        "duration_ms": 300, "method": "trapezoid"}))
        .await;
    let started = c.next_of("move_started").await;
    assert_eq!(started["ref_seq"], 6);
    assert_eq!(started["move"]["state"], "running");
    assert_eq!(started["move"]["method"], "trapezoid");
    let id = started["move"]["id"].clone();
    // Events reach every session (this one subscribed to nothing).
    loop {
        let ev = c.next_event().await;
        if ev["event"]["event"] == "move_done" {
            assert_eq!(ev["event"]["move_id"], id);
            break;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn setpoints_may_name_joints_by_hand_and_joint_name() {
    use jointd::hands::{resolve, HandConfig, HandJoints, Ids, StateStore};
    let bus = sim_bus::start(2, None).await;
    let hands = resolve(
        &[HandConfig {
            name: "left".into(),
            joints: vec![HandJoints {
                bus: "sim0".into(),
                ids: Ids::List(vec![1, 2]),
                names: vec!["thumb".into(), "index".into()],
            }],
        }],
        &["sim0".to_string()],
    )
    .expect("a hand");
    let store = StateStore::open(hands, None).expect("poses in memory");
    let options = jointd::control::Options {
        hands: Some(std::sync::Arc::new(store)),
        ..Default::default()
    };
    assert!(bus.server_state.control().set_options(options).is_ok());
    enable(&bus, &[1, 2]).await;
    let mut c = connect(&bus).await;
    c.send(json!({"type": "setpoints", "seq": 1, "ack": true,
        "targets": [{"hand": "left", "joint": "index", "position_deg": 12.5}]}))
        .await;
    assert_eq!(c.next_of("ack").await["ref_seq"], 1);
    bus.wait_snapshot("joint 2 targeted", |s| {
        s.devices[&2]
            .target_sent
            .is_some_and(|t| (jointd::protocol::units::angle_deg(t.pos_ref) - 12.5).abs() < 0.01)
    })
    .await;
    let e = c
        .rejected(json!({"type": "setpoints", "seq": 2,
            "targets": [{"hand": "left", "joint": "pinky", "position_deg": 1}]}))
        .await;
    assert_eq!(e["field"], "targets[0].joint");
    let e = c
        .rejected(json!({"type": "setpoints", "seq": 3,
            "targets": [{"hand": "left", "id": 1, "position_deg": 1}]}))
        .await;
    assert_eq!(
        (e["code"].as_str(), e["field"].as_str()),
        (Some("bad_message"), Some("targets[0]"))
    );
}

/// `enable`, `disable` and `estop` over the WebSocket go through the calls
/// REST makes: the same answers, and an unknown device refused in the
/// same words as REST refuses it.
#[tokio::test]
async fn enable_disable_and_estop_over_the_websocket_are_rests_calls() {
    let bus = sim_bus::start(2, None).await;
    let mut c = connect(&bus).await;
    c.send(json!({"type": "enable", "seq": 1, "bus": "sim0", "ids": [1]}))
        .await;
    let done = c.next_of("done").await;
    assert_eq!(done["ref_seq"], 1);
    assert_eq!(done["action"], "enable");
    assert_eq!(done["ids"], json!([1]));
    bus.wait_snapshot("joint 1 enabled", |s| {
        s.devices.get(&1).is_some_and(|d| {
            d.info01
                .as_ref()
                .is_some_and(|(i, _)| jointd::control::device::is_enabled(i))
        })
    })
    .await;
    // An unknown device: the core's refusal, word for word REST's.
    c.send(json!({"type": "enable", "seq": 2, "bus": "sim0", "ids": [9]}))
        .await;
    let refused = c.next_of("error").await;
    assert_eq!(refused["ref_seq"], 2);
    let rest = bus
        .server
        .post("/api/v1/buses/sim0/control/enable", json!({"ids": [9]}))
        .await;
    assert_eq!(
        refused["message"], rest.body["detail"],
        "one check, one wording"
    );
    c.send(json!({"type": "disable", "seq": 3, "bus": "sim0"}))
        .await;
    assert_eq!(c.next_of("done").await["action"], "disable");
    c.send(json!({"type": "estop", "seq": 4})).await;
    let stopped = c.next_of("estopped").await;
    assert_eq!(stopped["ref_seq"], 4);
    assert_eq!(stopped["result"]["stopped"], true, "{stopped}");
}
