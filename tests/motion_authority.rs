//! One authority over motion, against the simulator through REST: a
//! command admitted before an e-stop, a disable, a mode change or an enable
//! never drives the joint after it, and a move that cannot follow its path
//! says so.
//!
//! "The joint does not move" is checked without a time window: after the
//! step under test, a fence (a target for another joint, seen reaching the
//! simulated device) proves the owner has made frames since; the device's
//! own target and speed reference then show what reached it.

mod support;

use std::time::Duration;

use jointd::sim::Fault;
use serde_json::{json, Value};
use support::sim_bus::{start, SimBus, WAIT};

/// Puts joint `id` in `mode` over REST.
async fn set_mode(b: &SimBus, id: u8, mode: &str) {
    let r = b
        .server
        .put(
            &format!("/api/v1/buses/sim0/devices/{id}/mode"),
            json!({ "mode": mode }),
        )
        .await;
    assert!(r.status.is_success(), "mode {mode}: {}", r.body);
}

async fn post_move(b: &SimBus, id: u8, deg: f64, ms: u64) -> (u16, Value) {
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": id, "position_deg": deg}],
                   "duration_ms": ms, "method": "linear"}),
        )
        .await;
    (r.status.as_u16(), r.body.clone())
}

async fn move_view(b: &SimBus, move_id: u64) -> Value {
    b.server
        .get(&format!("/api/v1/moves/{move_id}"))
        .await
        .ok()
        .clone()
}

/// Waits until the simulator shows `pred` of device `id`.
fn sim_until(b: &SimBus, what: &str, pred: impl Fn(&jointd::sim::DeviceView) -> bool, id: u8) {
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        if b.sim.device(id).is_some_and(|d| pred(&d)) {
            return;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "timed out waiting for {what}: {:?}",
            b.sim.device(id)
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// A target for `fence_id` (enabled), seen on its simulated device: frames
/// were made after everything before this call.
async fn fence(b: &SimBus, fence_id: u8, deg: f64) {
    let r = b
        .server
        .put(
            &format!("/api/v1/buses/sim0/devices/{fence_id}/target"),
            json!({"position_deg": deg}),
        )
        .await;
    assert!(r.status.is_success(), "fence target: {}", r.body);
    sim_until(
        b,
        "the fence target on its device",
        |d| (d.target_deg - deg).abs() < 0.1,
        fence_id,
    );
}

fn device_target(b: &SimBus, id: u8) -> f64 {
    b.sim.device(id).expect("device").target_deg
}

fn is_running(view: &Value) -> bool {
    view["state"] == "running"
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_racing_an_estop_never_drives_the_joint_after_the_next_enable() {
    let b = start(2, None).await;
    b.enable_running(2).await;
    for attempt in 0..8u64 {
        b.enable_running(1).await;
        let held = b.sim.device(1).expect("device 1").angle_deg;
        let handle = b.handle.clone();
        let estop = tokio::spawn(async move { handle.estop().await });
        // The move goes in while the e-stop is on its way (0..7 ms later).
        tokio::time::sleep(Duration::from_millis(attempt)).await;
        let (status, body) = post_move(&b, 1, 60.0, 400).await;
        estop.await.expect("join").expect("e-stop");
        if status == 201 {
            let id = body["id"].as_u64().expect("move id");
            let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
            assert_eq!(view["state"], "aborted", "attempt {attempt}: {view}");
        } else {
            assert_eq!(status, 409, "attempt {attempt}: {body}");
        }
        b.enable_running(1).await;
        b.enable_running(2).await;
        fence(&b, 2, 10.0 + attempt as f64).await;
        let target = device_target(&b, 1);
        assert!(
            (target - held).abs() < 2.0 && target < 30.0,
            "attempt {attempt}: joint 1 holds a target of {target:.1}° after the enable \
             (it stood at {held:.1}°; the move went to 60°)"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_disable_mid_move_ends_it_and_an_enable_does_not_resume_it() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    let (status, body) = post_move(&b, 1, 80.0, 3000).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_u64().expect("move id");
    sim_until(&b, "joint 1 under way", |d| d.angle_deg > 5.0, 1);
    let r = b
        .server
        .post("/api/v1/buses/sim0/devices/1/disable", json!({}))
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(view["state"], "aborted", "{view}");
    assert_eq!(view["reason"], "disabled", "{view}");
    let progress = view["progress"].as_f64().expect("progress");
    b.enable_running(1).await;
    let held = b.sim.device(1).expect("device 1").angle_deg;
    fence(&b, 2, 12.0).await;
    let target = device_target(&b, 1);
    assert!(
        (target - held).abs() < 2.0,
        "joint 1 holds {target:.1}° after the enable, not where it stood ({held:.1}°)"
    );
    // An ended move's progress stays where it ended.
    let later = move_view(&b, id).await;
    assert_eq!(later["progress"].as_f64(), Some(progress), "{later}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mode_change_mid_move_ends_it_and_the_joint_does_not_spin() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    let (status, body) = post_move(&b, 1, 80.0, 3000).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_u64().expect("move id");
    sim_until(&b, "joint 1 under way", |d| d.angle_deg > 5.0, 1);
    set_mode(&b, 1, "speed").await;
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(view["state"], "aborted", "{view}");
    assert_eq!(view["reason"], "mode_changed", "{view}");
    fence(&b, 2, 14.0).await;
    let d = b.sim.device(1).expect("device 1");
    assert_eq!(
        d.spd_ref, 0,
        "joint 1 in speed mode was left a speed reference of {}: it spins",
        d.spd_ref
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_enable_in_speed_mode_after_an_estop_does_not_spin() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    set_mode(&b, 1, "speed").await;
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"speed_dps": 10.0}),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    sim_until(&b, "joint 1 spinning", |d| d.velocity_deg_s.abs() > 1.0, 1);
    b.handle.estop().await.expect("e-stop");
    b.enable_running(1).await;
    b.enable_running(2).await;
    fence(&b, 2, 16.0).await;
    let d = b.sim.device(1).expect("device 1");
    assert_eq!(
        d.spd_ref, 0,
        "joint 1 was enabled in speed mode with a speed reference of {}",
        d.spd_ref
    );
    let target = b
        .server
        .get("/api/v1/buses/sim0/devices/1")
        .await
        .ok()
        .clone();
    assert!(target["target"].is_null(), "{target}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_blocked_joint_stalls_its_move_instead_of_arriving() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    let (status, body) = post_move(&b, 1, 60.0, 1500).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_u64().expect("move id");
    sim_until(&b, "joint 1 past 10°", |d| d.angle_deg > 10.0, 1);
    b.sim.inject(Fault::Stall {
        dev_id: 1,
        at_deg: None,
    });
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(view["state"], "stalled", "{view}");
    assert_eq!(view["arrived"], json!([]), "{view}");
    assert_eq!(view["stalled"][0]["id"], 1, "{view}");
    // The hold reaches the wire just after the move says so.
    sim_until(
        &b,
        "a stalled joint holding where it stands",
        |d| (d.target_deg - d.angle_deg).abs() < 3.0,
        1,
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_says_what_it_cannot_apply_and_never_exceeds_a_speed_cap() {
    let b = start(2, None).await;
    b.enable_running(2).await;
    // Waypoints time themselves: a duration beside them would be ignored.
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 2}], "duration_ms": 500,
                   "waypoints": [{"at_ms": 300, "positions_deg": [10.0]}]}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "duration_ms", "{}", r.body);
    // Joint 2 is capped at 6000 rpm in the fixture; a path needing 5200
    // rpm gets frames with 1.25 x that, capped: never above 6000 rpm.
    let dist = 40.0;
    let peak_dps = 5200.0 * jointd::protocol::units::output_deg_per_s(1.0);
    let ms = (1.875 * dist / peak_dps * 1e3).ceil() as u64;
    let (status, body) = post_move(&b, 2, dist, ms).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_u64().expect("move id");
    b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    let frames = b
        .server
        .get("/api/v1/buses/sim0/frames?limit=512")
        .await
        .ok()
        .clone();
    let fastest = frames["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .filter_map(|f| f["decoded"]["spd_rpm"].as_f64())
        .fold(0.0, f64::max);
    assert!(fastest > 0.0, "no speed seen in the frames: {frames}");
    assert!(
        fastest <= 6000.0,
        "a frame carried {fastest} rpm against a 6000 rpm cap"
    );
}

/// The server's next message of `kind` (telemetry and events skipped).
async fn next_of<S>(ws: &mut S, kind: &str) -> Value
where
    S: futures_util::StreamExt<
            Item = Result<
                tokio_tungstenite::tungstenite::Message,
                tokio_tungstenite::tungstenite::Error,
            >,
        > + Unpin,
{
    let wait = async {
        while let Some(Ok(m)) = ws.next().await {
            if let tokio_tungstenite::tungstenite::Message::Text(t) = m {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                if v["type"] == kind {
                    return v;
                }
            }
        }
        panic!("socket closed before a `{kind}`");
    };
    tokio::time::timeout(WAIT, wait)
        .await
        .unwrap_or_else(|_| panic!("no `{kind}` message"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_teleop_stream_ended_by_an_estop_never_resumes_by_itself() {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message;
    let b = start(2, None).await;
    b.enable_running(1).await;
    let url = format!("{}/api/v1/ws", b.server.base.replace("http://", "ws://"));
    let (mut ws, _) = tokio_tungstenite::connect_async(url)
        .await
        .expect("connect");
    let batch = |seq: u64, deg: f64, restart: bool| {
        Message::text(
            json!({"type": "setpoints", "seq": seq, "ack": true, "restart": restart,
                   "targets": [{"bus": "sim0", "id": 1, "position_deg": deg}]})
            .to_string(),
        )
    };
    ws.send(batch(1, 5.0, false)).await.expect("send");
    assert_eq!(next_of(&mut ws, "ack").await["ref_seq"], 1);
    b.handle.estop().await.expect("e-stop");
    let ended = next_of(&mut ws, "stream_ended").await;
    assert_eq!(
        (ended["id"].as_u64(), ended["reason"].as_str()),
        (Some(1), Some("estopped")),
        "{ended}"
    );
    b.enable_running(1).await;
    b.enable_running(2).await;
    // The client streams on as if nothing happened: refused.
    ws.send(batch(2, 30.0, false)).await.expect("send");
    let refused = next_of(&mut ws, "error").await;
    assert_eq!(
        (refused["ref_seq"].as_u64(), refused["code"].as_str()),
        (Some(2), Some("wrong_state")),
        "{refused}"
    );
    fence(&b, 2, 11.0).await;
    assert!(
        device_target(&b, 1) < 20.0,
        "the ended stream drove joint 1 to {:.1}°",
        device_target(&b, 1)
    );
    // A new stream, asked for, is admitted.
    ws.send(batch(3, 30.0, true)).await.expect("send");
    assert_eq!(next_of(&mut ws, "ack").await["ref_seq"], 3);
}

/// A WebSocket session on the rig's server.
async fn ws_connect(
    b: &SimBus,
) -> tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>> {
    let url = format!("{}/api/v1/ws", b.server.base.replace("http://", "ws://"));
    tokio_tungstenite::connect_async(url)
        .await
        .expect("connect")
        .0
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_move_racing_an_estop_never_drives_the_joint_after_the_next_enable() {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message;
    let b = start(2, None).await;
    b.enable_running(2).await;
    let mut ws = ws_connect(&b).await;
    for attempt in 0..6u64 {
        b.enable_running(1).await;
        let held = b.sim.device(1).expect("device 1").angle_deg;
        let handle = b.handle.clone();
        let estop = tokio::spawn(async move { handle.estop().await });
        tokio::time::sleep(Duration::from_millis(attempt)).await;
        let seq = 100 + attempt;
        let mv = json!({"type": "move", "seq": seq, "duration_ms": 400, "method": "linear",
            "joints": [{"bus": "sim0", "id": 1, "position_deg": 60.0}]});
        ws.send(Message::text(mv.to_string())).await.expect("send");
        estop.await.expect("join").expect("e-stop");
        // Either refused or started (and then aborted by the e-stop).
        let answer = loop {
            let v = next_any(&mut ws).await;
            if v["ref_seq"] == seq {
                break v;
            }
        };
        if answer["type"] == "move_started" {
            let id = answer["move"]["id"].as_u64().expect("move id");
            let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
            assert_eq!(view["state"], "aborted", "attempt {attempt}: {view}");
        } else {
            assert_eq!(answer["code"], "wrong_state", "attempt {attempt}: {answer}");
        }
        b.enable_running(1).await;
        b.enable_running(2).await;
        fence(&b, 2, 20.0 + attempt as f64).await;
        let target = device_target(&b, 1);
        assert!(
            (target - held).abs() < 2.0 && target < 30.0,
            "attempt {attempt}: joint 1 holds {target:.1}° after the enable (stood at {held:.1}°)"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_speed_stream_does_not_spin_after_an_estop_and_enable() {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message;
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    set_mode(&b, 1, "speed").await;
    let mut ws = ws_connect(&b).await;
    let batch = json!({"type": "setpoints", "seq": 1, "ack": true,
        "targets": [{"bus": "sim0", "id": 1, "speed_dps": 10.0}]});
    ws.send(Message::text(batch.to_string()))
        .await
        .expect("send");
    assert_eq!(next_of(&mut ws, "ack").await["ref_seq"], 1);
    sim_until(&b, "joint 1 spinning", |d| d.velocity_deg_s.abs() > 1.0, 1);
    b.handle.estop().await.expect("e-stop");
    b.enable_running(1).await;
    b.enable_running(2).await;
    fence(&b, 2, 13.0).await;
    let d = b.sim.device(1).expect("device 1");
    assert_eq!(
        d.spd_ref, 0,
        "enabled in speed mode with {} (Q15)",
        d.spd_ref
    );
}

/// The server's next message, whatever its type.
async fn next_any<S>(ws: &mut S) -> Value
where
    S: futures_util::StreamExt<
            Item = Result<
                tokio_tungstenite::tungstenite::Message,
                tokio_tungstenite::tungstenite::Error,
            >,
        > + Unpin,
{
    let wait = async {
        while let Some(Ok(m)) = ws.next().await {
            if let tokio_tungstenite::tungstenite::Message::Text(t) = m {
                return serde_json::from_str::<Value>(t.as_str()).expect("JSON");
            }
        }
        panic!("socket closed");
    };
    tokio::time::timeout(WAIT, wait).await.expect("a message")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_enable_of_a_running_joint_holds_it_where_it_stands() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 80.0, "speed_dps": 10.0}),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    sim_until(&b, "joint 1 on its way", |d| d.angle_deg > 5.0, 1);
    // Enabled again while it runs: nothing from before this enable applies.
    b.enable_running(1).await;
    fence(&b, 2, 17.0).await;
    let d = b.sim.device(1).expect("device 1");
    assert!(
        d.target_deg < 60.0,
        "joint 1 still heads for the target set before its enable: {:.1}° (at {:.1}°)",
        d.target_deg,
        d.angle_deg
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rezero_mid_move_ends_the_move_and_the_joint_stays_enabled() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    let (status, body) = post_move(&b, 1, 60.0, 2000).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_u64().expect("move id");
    sim_until(&b, "joint 1 under way", |d| d.angle_deg > 5.0, 1);
    let r = b
        .server
        .post("/api/v1/buses/sim0/devices/1/rezero", json!({}))
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    // The path's angles meant the old zero: the move ends, not shifted.
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(
        (view["state"].as_str(), view["reason"].as_str()),
        (Some("aborted"), Some("zero_moved")),
        "{view}"
    );
    // Still enabled: a new target is admitted.
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 1.0}),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.body);
}

/// Starts a move over the WebSocket; its id.
async fn ws_move<S>(ws: &mut S, seq: u64, deg: f64, ms: u64) -> u64
where
    S: futures_util::Sink<tokio_tungstenite::tungstenite::Message>
        + futures_util::StreamExt<
            Item = Result<
                tokio_tungstenite::tungstenite::Message,
                tokio_tungstenite::tungstenite::Error,
            >,
        > + Unpin,
    <S as futures_util::Sink<tokio_tungstenite::tungstenite::Message>>::Error: std::fmt::Debug,
{
    use futures_util::SinkExt;
    let mv = json!({"type": "move", "seq": seq, "duration_ms": ms, "method": "linear",
        "joints": [{"bus": "sim0", "id": 1, "position_deg": deg}]});
    ws.send(tokio_tungstenite::tungstenite::Message::text(
        mv.to_string(),
    ))
    .await
    .expect("send");
    let started = next_of(ws, "move_started").await;
    assert_eq!(started["ref_seq"], seq, "{started}");
    started["move"]["id"].as_u64().expect("move id")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_move_ends_at_a_disable_and_an_enable_does_not_resume_it() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    b.enable_running(2).await;
    let mut ws = ws_connect(&b).await;
    let id = ws_move(&mut ws, 1, 80.0, 3000).await;
    sim_until(&b, "joint 1 under way", |d| d.angle_deg > 5.0, 1);
    let r = b
        .server
        .post("/api/v1/buses/sim0/devices/1/disable", json!({}))
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(
        (view["state"].as_str(), view["reason"].as_str()),
        (Some("aborted"), Some("disabled")),
        "{view}"
    );
    b.enable_running(1).await;
    let held = b.sim.device(1).expect("device 1").angle_deg;
    fence(&b, 2, 12.0).await;
    let target = device_target(&b, 1);
    assert!(
        (target - held).abs() < 2.0,
        "joint 1 holds {target:.1}° after the enable, not where it stood ({held:.1}°)"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_move_of_a_blocked_joint_stalls() {
    let b = start(2, None).await;
    b.enable_running(1).await;
    let mut ws = ws_connect(&b).await;
    let id = ws_move(&mut ws, 1, 60.0, 1500).await;
    sim_until(&b, "joint 1 past 10°", |d| d.angle_deg > 10.0, 1);
    b.sim.inject(Fault::Stall {
        dev_id: 1,
        at_deg: None,
    });
    let view = b.wait_move(id, "the move ended", |v| !is_running(v)).await;
    assert_eq!(view["state"], "stalled", "{view}");
    assert_eq!(view["arrived"], json!([]), "{view}");
}
