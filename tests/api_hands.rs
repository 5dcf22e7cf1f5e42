//! Named hands and poses through the real binary: a `[[hand]]`
//! of the simulated bus, a pose saved, the daemon stopped and started again
//! on the same state directory with the pose still there, and going to it
//! as a move; bad poses and names get a 4xx that says what was wrong.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

mod support;
use support::daemon::{Daemon, WAIT};
use support::tmp::TestDir;

/// `jointd --sim 4` with `config`.
fn start(config: &std::path::Path) -> Daemon {
    let config = config.to_str().expect("utf-8 path");
    Daemon::spawn(&["--sim", "4", "--listen", "127.0.0.1:0", "--config", config])
}

async fn call(method: reqwest::Method, url: String, body: Option<Value>) -> (u16, Value) {
    let client = reqwest::Client::new();
    let mut req = client.request(method, url);
    if let Some(b) = body {
        req = req.json(&b);
    }
    let r = req.send().await.expect("request");
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

async fn wait_online(base: &str) {
    let deadline = Instant::now() + WAIT;
    loop {
        let (_, bus) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/buses/sim0"),
            None,
        )
        .await;
        if bus["devices_online"] == 4 {
            return;
        }
        assert!(Instant::now() < deadline, "joints never online: {bus}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[test]
fn a_pose_survives_a_restart_and_a_hand_goes_to_it() {
    let dir = std::env::temp_dir().join(format!("jointd-hands-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("jointd.toml");
    std::fs::write(
        &config,
        format!(
            r#"state_dir = "{}"

[[hand]]
name = "left"
joints = [{{ bus = "sim0", ids = "1-2", names = ["thumb", "index"] }}, {{ bus = "sim0", ids = 3 }}]

[[limit]]
ids = [2]
min_deg = -45.0
max_deg = 45.0
"#,
            dir.join("state").display()
        ),
    )
    .unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let fist = json!({"thumb": 20.0, "index": 30.0, "sim0_3": -10.0});

    let mut d = start(&config);
    rt.block_on(async {
        let base = &d.base;
        wait_online(base).await;
        let (s, hands) = call(reqwest::Method::GET, format!("{base}/api/v1/hands"), None).await;
        assert_eq!(s, 200);
        assert_eq!(hands["hands"][0]["name"], "left");
        let names: Vec<&str> = hands["hands"][0]["joints"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|j| j["name"].as_str())
            .collect();
        assert_eq!(names, ["thumb", "index", "sim0_3"]);
        // The device list names a hand's joints as the hand does (the
        // dashboard's table shows this name).
        let (s, devices) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/buses/sim0/devices"),
            None,
        )
        .await;
        assert_eq!(s, 200);
        let named: Vec<(u64, Value)> = devices["devices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| (d["id"].as_u64().unwrap_or(0), d["name"].clone()))
            .collect();
        assert_eq!(named[0], (1, json!("thumb")), "{devices}");
        assert_eq!(named[1], (2, json!("index")), "{devices}");
        let put = |name: &str, body: Value| {
            call(
                reqwest::Method::PUT,
                format!("{base}/api/v1/hands/left/poses/{name}"),
                Some(body),
            )
        };
        let (s, saved) = put("fist", json!({ "positions_deg": fist })).await;
        assert_eq!(s, 200, "{saved}");
        assert_eq!(saved["positions_deg"], fist);
        // Outside joint 2's soft limit, an unknown joint, a bad name: 422, nothing saved.
        let (s, p) = put("wide", json!({"positions_deg": {"index": 60.0}})).await;
        assert_eq!((s, p["field"].as_str()), (422, Some("positions_deg.index")));
        let (s, p) = put("odd", json!({"positions_deg": {"pinky": 1.0}})).await;
        assert_eq!((s, p["field"].as_str()), (422, Some("positions_deg.pinky")));
        let (s, _) = put("bad%20name", json!({"positions_deg": {"thumb": 1.0}})).await;
        assert_eq!(s, 422);
        let (s, _) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/hands/left/poses/wide"),
            None,
        )
        .await;
        assert_eq!(s, 404);
        let (s, _) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/hands/right/poses/fist"),
            None,
        )
        .await;
        assert_eq!(s, 404);
        // A calibration goes to the same state file.
        let (s, cal) = call(
            reqwest::Method::PUT,
            format!("{base}/api/v1/buses/sim0/devices/3/calibration"),
            Some(json!({"offset_deg": 4.5, "flip": true, "range_deg": [-30.0, 30.0]})),
        )
        .await;
        assert_eq!(s, 200, "{cal}");
    });
    d.stop();

    // Started again on the same state directory: the pose is there.
    let mut d = start(&config);
    rt.block_on(async {
        let base = &d.base;
        wait_online(base).await;
        let (s, pose) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/hands/left/poses/fist"),
            None,
        )
        .await;
        assert_eq!(s, 200);
        assert_eq!(pose["positions_deg"], fist);
        let (s, cal) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/hands/left/calibration"),
            None,
        )
        .await;
        assert_eq!(s, 200);
        let third = &cal["joints"][2];
        assert_eq!(third["joint"], "sim0_3", "{cal}");
        assert_eq!(third["calibration"]["offset_deg"], 4.5, "{cal}");
        assert_eq!(third["calibration"]["flip"], true, "{cal}");
        assert_eq!(cal["joints"][0]["calibration"]["offset_deg"], 0.0, "{cal}");
        // Going to it needs the joints enabled: 409 first, then a move.
        let go = || {
            call(
                reqwest::Method::POST,
                format!("{base}/api/v1/hands/left/poses/fist/go"),
                Some(json!({"duration_ms": 500, "method": "min_jerk"})),
            )
        };
        let (s, _) = go().await;
        assert_eq!(s, 409);
        let (s, _) = call(
            reqwest::Method::POST,
            format!("{base}/api/v1/buses/sim0/control/enable"),
            Some(json!({"ids": [1, 2, 3]})),
        )
        .await;
        assert_eq!(s, 200);
        let deadline = Instant::now() + WAIT;
        let started = loop {
            let (s, body) = go().await;
            if s == 201 {
                break body;
            }
            // Aligning after the enable: not yet running.
            assert!(s == 409 && Instant::now() < deadline, "{s} {body}");
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        let id = started["id"].as_u64().expect("a move id");
        assert_eq!(started["joints"].as_array().map(Vec::len), Some(3));
        let deadline = Instant::now() + WAIT;
        loop {
            let (_, mv) = call(
                reqwest::Method::GET,
                format!("{base}/api/v1/moves/{id}"),
                None,
            )
            .await;
            if mv["state"] == "done" {
                break;
            }
            assert!(Instant::now() < deadline, "move never done: {mv}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        // A move may name joints by hand and joint name.
        let by_name = |joint: Value| {
            call(
                reqwest::Method::POST,
                format!("{base}/api/v1/moves"),
                Some(json!({"joints": [joint], "duration_ms": 200})),
            )
        };
        let (s, mv) = by_name(json!({"hand": "left", "joint": "thumb", "position_deg": 5.0})).await;
        assert_eq!(s, 201, "{mv}");
        assert_eq!(mv["joints"], json!([{"bus": "sim0", "id": 1}]));
        let (s, p) = by_name(json!({"hand": "left", "joint": "pinky", "position_deg": 5.0})).await;
        assert_eq!((s, p["field"].as_str()), (422, Some("joints[0].joint")));
        let (s, p) = by_name(json!({"hand": "left", "bus": "sim0", "position_deg": 5.0})).await;
        assert_eq!((s, p["field"].as_str()), (422, Some("joints[0]")));
        // Deleted, and gone.
        let (s, _) = call(
            reqwest::Method::DELETE,
            format!("{base}/api/v1/hands/left/poses/fist"),
            None,
        )
        .await;
        assert_eq!(s, 200);
        let (s, _) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/hands/left/poses/fist"),
            None,
        )
        .await;
        assert_eq!(s, 404);
    });
    d.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A daemon killed (SIGKILL) while eight clients save poses at once, 8
/// times at different moments: the state file is always whole JSON with no
/// pose lost that an earlier round saved, never a torn write (a writer that
/// truncates and writes the file in place fails it).
#[test]
fn a_kill_during_pose_writes_leaves_a_whole_state_file() {
    let dir = std::env::temp_dir().join(format!("jointd-hands-kill-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let state = dir.join("state");
    let config = dir.join("jointd.toml");
    std::fs::write(
        &config,
        format!(
            "state_dir = \"{}\"\n\n[[hand]]\nname = \"left\"\njoints = [{{ bus = \"sim0\", ids = \"1-4\" }}]\n",
            state.display()
        ),
    )
    .unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let mut saved_before = 0usize;
    for round in 0..8u64 {
        let mut d = start(&config);
        let base = d.base.clone();
        let sent = rt.block_on(async move {
            // Eight clients saving poses at once, so a write is under way
            // when the kill comes; each goes on until the daemon is gone.
            let answered = Arc::new(AtomicU64::new(0));
            let mut clients = Vec::new();
            for c in 0..8u64 {
                let base = base.clone();
                let answered = answered.clone();
                clients.push(tokio::spawn(async move {
                    let client = reqwest::Client::new();
                    let mut k = 0u64;
                    loop {
                        let positions: serde_json::Map<String, Value> = (1..=4)
                            .map(|j| (format!("sim0_{j}"), json!(((c * 7 + k) % 90) as f64 + 0.25)))
                            .collect();
                        let r = client
                            .put(format!("{base}/api/v1/hands/left/poses/p{c}_{}", k % 20))
                            .json(&json!({ "positions_deg": positions }))
                            .send()
                            .await;
                        let Ok(r) = r else {
                            break; // the daemon is gone
                        };
                        if r.status() == 200 {
                            answered.fetch_add(1, Ordering::Relaxed);
                        }
                        k += 1;
                    }
                    k
                }));
            }
            // The kill comes a different time after the first pose was
            // saved in each round, while the clients keep writing: however
            // slowly a loaded host starts the daemon, there is a file.
            let deadline = Instant::now() + WAIT;
            while answered.load(Ordering::Relaxed) == 0 {
                assert!(Instant::now() < deadline, "round {round}: no pose saved");
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            tokio::time::sleep(Duration::from_millis(17 * round)).await;
            d.kill();
            let mut sent = 0;
            for c in clients {
                sent += c.await.unwrap_or(0);
            }
            sent
        });
        let Ok(text) = std::fs::read_to_string(state.join("state.json")) else {
            // Killed before its first write completed: nothing to tear yet.
            assert_eq!(saved_before, 0, "round {round}: the state file vanished");
            continue;
        };
        let parsed: Value = serde_json::from_str(&text)
            .unwrap_or_else(|e| panic!("round {round}: torn state file ({e}): {text}"));
        let poses = parsed["poses"]["left"].as_object().map_or(0, |p| p.len());
        assert!(poses >= saved_before, "round {round}: poses lost");
        assert!(sent > 0, "round {round}: no write went out");
        saved_before = poses;
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A program streaming setpoints to a hand's joints is shown on the hand
/// (`streamed_by`, with the name it gave) and on each joint, while it
/// streams; an e-stop ends its streams and takes it off; a new connection
/// that only reads is never shown; a name that cannot be shown is a 400.
#[test]
fn a_streaming_client_is_shown_on_its_hand_until_its_streams_end() {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;

    let dir = TestDir::new("hands-stream");
    let config = dir.join("jointd.toml");
    std::fs::write(
        &config,
        r#"[[hand]]
name = "left"
joints = [{ bus = "sim0", ids = "1-2", names = ["thumb", "index"] }]
"#,
    )
    .unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let d = start(&config);
    rt.block_on(async {
        let base = &d.base;
        wait_online(base).await;
        let ws_base = base.replace("http://", "ws://");
        let refused = tokio_tungstenite::connect_async(format!("{ws_base}/api/v1/ws?client=")).await;
        assert!(
            matches!(&refused, Err(tokio_tungstenite::tungstenite::Error::Http(r)) if r.status() == 400),
            "an empty name: {refused:?}"
        );
        let (s, _) = call(
            reqwest::Method::POST,
            format!("{base}/api/v1/buses/sim0/control/enable"),
            Some(json!({"ids": [1, 2]})),
        )
        .await;
        assert_eq!(s, 200);
        let hands = || async {
            call(reqwest::Method::GET, format!("{base}/api/v1/hands"), None)
                .await
                .1
        };
        let (mut ws, _) =
            tokio_tungstenite::connect_async(format!("{ws_base}/api/v1/ws?client=lerobot%20follower"))
                .await
                .expect("connect");
        let welcome: Value = match ws.next().await {
            Some(Ok(Message::Text(t))) => serde_json::from_str(t.as_str()).unwrap(),
            other => panic!("no welcome: {other:?}"),
        };
        assert_eq!(welcome["name"], "lerobot follower");
        assert!(hands().await["hands"][0]["streamed_by"]
            .as_array()
            .is_some_and(|a| a.is_empty()));
        // Targets go in once the joints run (a target while they align is refused).
        let deadline = Instant::now() + WAIT;
        loop {
            ws.send(Message::text(
                json!({"type": "setpoints", "seq": 1, "ack": true, "targets": [
                    {"hand": "left", "joint": "index", "position_deg": 5.0}]})
                .to_string(),
            ))
            .await
            .expect("send");
            let reply: Value = loop {
                if let Some(Ok(Message::Text(t))) = ws.next().await {
                    let v: Value = serde_json::from_str(t.as_str()).unwrap();
                    if v["type"] == "ack" || v["type"] == "error" {
                        break v;
                    }
                }
            };
            if reply["type"] == "ack" {
                break;
            }
            assert!(Instant::now() < deadline, "never accepted: {reply}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let shown = hands().await["hands"][0]["streamed_by"].clone();
        assert_eq!(shown.as_array().map(Vec::len), Some(1), "{shown}");
        assert_eq!(shown[0]["via"], "websocket");
        assert_eq!(shown[0]["name"], "lerobot follower");
        assert_eq!(shown[0]["client"], welcome["client"]);
        assert_eq!(shown[0]["joints"], json!(["index"]));
        let (_, index) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/buses/sim0/devices/2"),
            None,
        )
        .await;
        assert_eq!(index["streamed_by"]["name"], "lerobot follower");
        let (_, thumb) = call(
            reqwest::Method::GET,
            format!("{base}/api/v1/buses/sim0/devices/1"),
            None,
        )
        .await;
        assert_eq!(thumb["streamed_by"], Value::Null);

        let (s, _) = call(reqwest::Method::POST, format!("{base}/api/v1/estop"), None).await;
        assert_eq!(s, 200);
        let deadline = Instant::now() + WAIT;
        while !hands().await["hands"][0]["streamed_by"]
            .as_array()
            .is_some_and(|a| a.is_empty())
        {
            assert!(Instant::now() < deadline, "still shown after the e-stop");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        drop(ws);
    });
}
