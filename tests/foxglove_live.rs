//! The live Foxglove view of a `--sim 16` daemon, as the Foxglove app sees
//! it: a WebSocket client speaking Foxglove's protocol (subprotocol
//! `foxglove.sdk.v1`, which the SDK's server negotiates) reads
//! `serverInfo` and `advertise`, finds every channel a recording declares
//! with the same encoding, schema and metadata, subscribes to the joint
//! states and decodes them as the advertised schema says (CDR,
//! `sensor_msgs/msg/JointState`, with the project's own decoder). Their
//! rate, counted by their log times, is the telemetry rate the API
//! reports; a client that stalls beside it changes neither. Bad and taken
//! addresses stop the daemon naming `--foxglove`.

mod support;

use std::collections::BTreeMap;
use std::io::Read;
use std::net::SocketAddr;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio::net::{TcpSocket, TcpStream};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::handshake::client::Request;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{client_async, connect_async, MaybeTlsStream, WebSocketStream};

use jointd::record::channels::{specs, SideEncoding, OFFERED_QOS_PROFILES};
use jointd::rosmsg::{JointState, JOINT_STATE_MSG};
use support::daemon::{wait_online, Daemon, WAIT};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// The subprotocol of Foxglove's WebSocket protocol the SDK's server speaks.
const SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// `messageData`'s opcode (a binary message's first byte).
const MESSAGE_DATA: u8 = 1;
const JOINTS: usize = 16;
const JOINT_STATES: &str = "/sim0/joint_states";
/// Joint states read per stretch, between two readings of the API's rate
/// (about a second each at the simulator's ~43 Hz per joint).
const STRETCH: usize = 40;
/// How far the live rate may be from the API's: the API counts in 1 s
/// windows, the live view by the wire times of a few seconds of messages
/// (the Python recording test allows the same).
const RATE_TOLERANCE: f64 = 0.10;

/// A `--sim 16` daemon with the live view on a port the system picks, and
/// the view's url as its log says it.
async fn start() -> (Daemon, String, reqwest::Client) {
    let mut d = Daemon::start_with(&["--sim", "16", "--foxglove", "127.0.0.1:0"], |_| {});
    let line = d.log_line(&["Foxglove live view", "ws://"]);
    let at = line.find("ws://").expect("a url");
    let url = line[at..]
        .split_whitespace()
        .next()
        .expect("a url")
        .to_owned();
    let http = reqwest::Client::new();
    wait_online(&http, &mut d, JOINTS, WAIT).await;
    (d, url, http)
}

/// The opening request of a client offering Foxglove's subprotocol.
fn request(url: &str) -> Request {
    let mut req = url.into_client_request().expect("a ws url");
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static(SUBPROTOCOL),
    );
    req
}

/// A client; the server must pick Foxglove's subprotocol.
async fn connect(url: &str) -> Ws {
    let (ws, response) = tokio::time::timeout(WAIT, connect_async(request(url)))
        .await
        .expect("connected in time")
        .expect("connected");
    let picked = response.headers().get("sec-websocket-protocol");
    assert_eq!(picked.and_then(|v| v.to_str().ok()), Some(SUBPROTOCOL));
    ws
}

/// A client whose socket takes little (a 4 KB receive buffer): stalled,
/// it fills the server's side of the connection soon.
async fn connect_small(url: &str) -> Ws {
    let addr: SocketAddr = url.trim_start_matches("ws://").parse().expect("IP:PORT");
    let socket = TcpSocket::new_v4().expect("a socket");
    socket.set_recv_buffer_size(4096).expect("SO_RCVBUF");
    let stream = socket.connect(addr).await.expect("connected");
    let (ws, _) = client_async(request(url), MaybeTlsStream::Plain(stream))
        .await
        .expect("the handshake");
    ws
}

/// The next JSON message whose `op` is `op` (others and binary skipped).
async fn next_op(ws: &mut Ws, op: &str) -> Value {
    let wait = async {
        loop {
            match ws.next().await {
                Some(Ok(Message::Text(t))) => {
                    let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                    if v["op"] == op {
                        return v;
                    }
                }
                Some(Ok(_)) => continue,
                other => panic!("the connection ended waiting for `{op}`: {other:?}"),
            }
        }
    };
    tokio::time::timeout(WAIT, wait)
        .await
        .unwrap_or_else(|_| panic!("no `{op}`"))
}

/// `serverInfo`, then the channels advertised until `n` are known.
async fn handshake(ws: &mut Ws, n: usize) -> (Value, Vec<Value>) {
    let info = next_op(ws, "serverInfo").await;
    let mut channels = Vec::new();
    while channels.len() < n {
        let adv = next_op(ws, "advertise").await;
        channels.extend(
            adv["channels"]
                .as_array()
                .expect("channels")
                .iter()
                .cloned(),
        );
    }
    (info, channels)
}

/// The advertised channel of `topic`.
fn channel<'a>(channels: &'a [Value], topic: &str) -> &'a Value {
    channels
        .iter()
        .find(|c| c["topic"] == topic)
        .unwrap_or_else(|| panic!("{topic} not advertised: {channels:?}"))
}

async fn subscribe(ws: &mut Ws, subscriptions: Value) {
    let msg = json!({"op": "subscribe", "subscriptions": subscriptions});
    ws.send(Message::text(msg.to_string()))
        .await
        .expect("subscribe");
}

/// A binary `messageData`: opcode 1, the subscription id (u32 LE), the
/// log time (u64 LE, Unix ns), the message.
fn message_data(b: &[u8]) -> Option<(u32, u64, &[u8])> {
    let (&op, rest) = b.split_first()?;
    if op != MESSAGE_DATA || rest.len() < 12 {
        return None;
    }
    let sub = u32::from_le_bytes(rest[..4].try_into().ok()?);
    let log_ns = u64::from_le_bytes(rest[4..12].try_into().ok()?);
    Some((sub, log_ns, &rest[12..]))
}

/// The next `n` messages of subscription `sub`, decoded as JointState
/// (CDR): (log time, message).
async fn joint_states(ws: &mut Ws, sub: u32, n: usize) -> Vec<(u64, JointState)> {
    let wait = async {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            match ws.next().await {
                Some(Ok(Message::Binary(b))) => {
                    let Some((id, log_ns, payload)) = message_data(&b) else {
                        continue;
                    };
                    assert_eq!(id, sub, "only the joint states are subscribed");
                    let msg = JointState::from_cdr(payload).expect("CDR as the schema says");
                    out.push((log_ns, msg));
                }
                Some(Ok(_)) => continue,
                other => panic!(
                    "the connection ended after {} joint states: {other:?}",
                    out.len()
                ),
            }
        }
        out
    };
    tokio::time::timeout(WAIT, wait)
        .await
        .unwrap_or_else(|_| panic!("fewer than {n} joint states within {WAIT:?}"))
}

/// The telemetry rate the API reports, averaged over the joints, Hz.
async fn telemetry_hz(http: &reqwest::Client, d: &Daemon) -> f64 {
    let v: Value = http
        .get(d.url("/api/v1/buses/sim0/devices"))
        .send()
        .await
        .expect("devices")
        .json()
        .await
        .expect("JSON");
    let devices = v["devices"].as_array().expect("devices");
    let sum: f64 = devices
        .iter()
        .map(|d| d["telemetry_hz"].as_f64().expect("telemetry_hz"))
        .sum();
    sum / devices.len() as f64
}

/// Joint states of subscription `sub` once steady: two stretches read and
/// dropped (the API's 1 s window then holds no start-up), then three
/// stretches, with the API's rate read before and after each (their mean).
async fn read_with_rates(
    ws: &mut Ws,
    sub: u32,
    http: &reqwest::Client,
    d: &Daemon,
) -> (Vec<(u64, JointState)>, f64) {
    let _warm_up = joint_states(ws, sub, 2 * STRETCH).await;
    let mut rates = vec![telemetry_hz(http, d).await];
    let mut states = Vec::new();
    for _ in 0..3 {
        states.extend(joint_states(ws, sub, STRETCH).await);
        rates.push(telemetry_hz(http, d).await);
    }
    let mean = rates.iter().sum::<f64>() / rates.len() as f64;
    (states, mean)
}

/// Messages per second by their log times: (count − 1) / span.
fn rate_by_log_time(states: &[(u64, JointState)]) -> f64 {
    let (first, last) = (states[0].0, states[states.len() - 1].0);
    let span_s = (last - first) as f64 / 1e9;
    (states.len() - 1) as f64 / span_s
}

/// Every joint named, in id order, with its three values; the stamp is the
/// log time (as in a recording); log times strictly increase.
fn check_messages(states: &[(u64, JointState)]) {
    let names: Vec<String> = (1..=JOINTS).map(|id| format!("sim0_{id}")).collect();
    for (log_ns, msg) in states {
        assert_eq!(msg.name, names);
        assert_eq!(msg.frame_id, "sim0");
        let lens = (msg.position.len(), msg.velocity.len(), msg.effort.len());
        assert_eq!(lens, (JOINTS, JOINTS, JOINTS));
        assert_eq!(
            msg.stamp_ns, *log_ns,
            "log time = the newest reply's wire time"
        );
    }
    for pair in states.windows(2) {
        assert!(pair[0].0 < pair[1].0, "log times in order, none twice");
    }
}

/// The sample `name` (no labels) of `/metrics`.
async fn metric(http: &reqwest::Client, d: &Daemon, name: &str) -> f64 {
    let text = http
        .get(d.url("/metrics"))
        .send()
        .await
        .expect("/metrics")
        .text()
        .await
        .expect("text");
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in /metrics:\n{text}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn joint_states_arrive_decoded_at_the_telemetry_rate() {
    let (d, url, http) = start().await;
    let mut ws = connect(&url).await;
    let (info, channels) = handshake(&mut ws, 4).await;
    let name = info["name"].as_str().expect("a name");
    assert!(name.starts_with("jointd"), "{info}");
    assert_eq!(info["capabilities"], json!([]), "read only: {info}");
    // The channels of a (default) recording of bus sim0, as it declares them.
    for spec in specs("sim0", SideEncoding::Json) {
        let c = channel(&channels, &spec.name);
        assert_eq!(c["encoding"], spec.encoding, "{}", spec.name);
        assert_eq!(c["schemaName"], spec.schema_name, "{}", spec.name);
        assert_eq!(c["schemaEncoding"], spec.schema_encoding, "{}", spec.name);
        assert_eq!(c["schema"], spec.schema.as_str(), "{}", spec.name);
        let metadata = c.get("metadata").cloned().unwrap_or_else(|| json!({}));
        let metadata: BTreeMap<String, String> = serde_json::from_value(metadata).expect("a map");
        assert_eq!(metadata, spec.metadata, "{}", spec.name);
    }
    assert_eq!(channels.len(), 4, "{channels:?}");
    let js = channel(&channels, JOINT_STATES);
    assert_eq!(js["encoding"], "cdr");
    assert_eq!(js["schemaName"], "sensor_msgs/msg/JointState");
    assert_eq!(js["schemaEncoding"], "ros2msg");
    assert_eq!(js["schema"], JOINT_STATE_MSG);
    assert_eq!(js["metadata"]["offered_qos_profiles"], OFFERED_QOS_PROFILES);

    const SUB: u32 = 7;
    subscribe(&mut ws, json!([{"id": SUB, "channelId": js["id"]}])).await;
    let (states, api_hz) = read_with_rates(&mut ws, SUB, &http, &d).await;
    check_messages(&states);
    let live_hz = rate_by_log_time(&states);
    assert!(
        (live_hz - api_hz).abs() / api_hz < RATE_TOLERANCE,
        "{live_hz:.1} joint states/s live against {api_hz:.1} Hz telemetry"
    );
    // The counters: this client, and at least what it read.
    assert_eq!(metric(&http, &d, "jointd_foxglove_enabled").await, 1.0);
    assert_eq!(metric(&http, &d, "jointd_foxglove_clients").await, 1.0);
    let logged = metric(&http, &d, "jointd_foxglove_messages_total").await;
    assert!(logged >= states.len() as f64, "{logged} logged");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_client_slows_neither_another_client_nor_the_bus() {
    let (mut d, url, http) = start().await;
    let mut ws = connect(&url).await;
    let (_, channels) = handshake(&mut ws, 4).await;
    const SUB: u32 = 1;
    let js = channel(&channels, JOINT_STATES);
    subscribe(&mut ws, json!([{"id": SUB, "channelId": js["id"]}])).await;
    let (_, alone_hz) = read_with_rates(&mut ws, SUB, &http, &d).await;
    // Subscribed to every channel (the frames' thousands a second among
    // them) and never read again.
    let mut stalled = connect_small(&url).await;
    let (_, all) = handshake(&mut stalled, 4).await;
    let every: Vec<Value> = all
        .iter()
        .enumerate()
        .map(|(i, c)| json!({"id": i + 1, "channelId": c["id"]}))
        .collect();
    subscribe(&mut stalled, Value::Array(every)).await;
    // Until its socket and its queue are full: the SDK says when it drops
    // a client's oldest messages (meanwhile the other client's joint
    // states wait in its own queue, far from full).
    d.log_line(&["outbox for client", "full"]);
    let (states, api_hz) = read_with_rates(&mut ws, SUB, &http, &d).await;
    check_messages(&states);
    let live_hz = rate_by_log_time(&states);
    assert!(
        (live_hz - api_hz).abs() / api_hz < RATE_TOLERANCE,
        "{live_hz:.1} joint states/s live against {api_hz:.1} Hz telemetry, beside a stalled client"
    );
    assert!(
        api_hz > alone_hz * (1.0 - RATE_TOLERANCE),
        "the bus's telemetry fell from {alone_hz:.1} Hz to {api_hz:.1} Hz with a client stalled"
    );
    assert_eq!(metric(&http, &d, "jointd_foxglove_clients").await, 2.0);
    drop(stalled);
}

/// Runs `cmd` until it exits (killed and failed after [`WAIT`]): its
/// status and what it wrote to stderr.
fn run_to_exit(mut cmd: Command) -> (ExitStatus, String) {
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn jointd");
    let deadline = Instant::now() + WAIT;
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            panic!("jointd kept running");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    let _ = child
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut err);
    (status, err)
}

#[test]
fn a_bad_address_is_refused_naming_the_flag() {
    let cmd = Daemon::command(&[
        "--sim",
        "1",
        "--listen",
        "127.0.0.1:0",
        "--foxglove",
        "localhost:8765",
    ]);
    let (status, err) = run_to_exit(cmd);
    assert!(!status.success(), "{err}");
    assert!(err.contains("--foxglove"), "{err}");
    assert!(err.contains("neither a port"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_taken_address_stops_a_second_daemon_naming_the_flag() {
    let (_d, url, _) = start().await;
    let taken = url.trim_start_matches("ws://").to_owned();
    let cmd = Daemon::command(&[
        "--sim",
        "1",
        "--listen",
        "127.0.0.1:0",
        "--foxglove",
        taken.as_str(),
    ]);
    let (status, err) = tokio::task::spawn_blocking(move || run_to_exit(cmd))
        .await
        .expect("ran");
    assert!(!status.success(), "{err}");
    assert!(err.contains("cannot listen for Foxglove"), "{err}");
    assert!(err.contains("--foxglove"), "{err}");
}
