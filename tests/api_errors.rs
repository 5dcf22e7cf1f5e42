//! The API over HTTP against a scripted bus owner: every error status, auth
//! on and off, soft limits, and what each endpoint asks of the bus.

mod support;

use std::sync::atomic::Ordering;
use std::time::Duration;

use jointd::control::limits::{LimitRule, SoftLimits};
use jointd::http::AppState;
use serde_json::json;
use support::fake_bus::FakeBus;
use support::http::{serve, Server};

const DEV: &str = "/api/v1/buses/fake/devices";

fn limits() -> SoftLimits {
    SoftLimits::new(vec![LimitRule {
        bus: Some("fake".into()),
        ids: vec![2],
        min_deg: Some(-90.0),
        max_deg: Some(90.0),
        max_speed_dps: Some(40.0),
        max_rpm: None,
    }])
    .unwrap()
}

async fn setup(token: Option<&str>) -> (FakeBus, Server) {
    let bus = FakeBus::new("fake", &[1, 2, 3]);
    let state = AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            limits(),
        )),
        token.map(str::to_owned),
    );
    let server = serve(state).await;
    (bus, server)
}

#[tokio::test]
async fn auth_on_requires_the_bearer_token_everywhere_but_healthz() {
    let (_bus, server) = setup(Some("s3cret")).await;
    server.get("/healthz").await.ok();
    let r = server.get("/api/v1/buses").await;
    r.problem(401);
    assert_eq!(r.headers["www-authenticate"], "Bearer");
    server.get("/openapi.json").await.problem(401);
    server.get("/metrics").await.problem(401);
    let wrong = server.with_token("s3creT");
    wrong.get("/api/v1/buses").await.problem(401);
    let right = wrong.with_token("s3cret");
    assert_eq!(
        right.get("/api/v1/buses").await.ok()["buses"][0]["name"],
        "fake"
    );
    right.get("/readyz").await.ok();
}

#[tokio::test]
async fn auth_off_serves_without_a_token() {
    let (_bus, server) = setup(None).await;
    server.get("/api/v1/buses").await.ok();
    server.get(DEV).await.ok();
}

#[tokio::test]
async fn bad_input_gets_400_404_405_415_422_never_500() {
    let (_bus, s) = setup(None).await;
    s.get("/api/v1/buses/nope").await.problem(404);
    s.get(&format!("{DEV}/9")).await.problem(404);
    s.get("/api/v1/nothing-here").await.problem(404);
    let r = s.get(&format!("{DEV}/200")).await;
    let p = r.problem(422);
    assert_eq!(p["field"], "id");
    assert_eq!(
        (p["allowed"]["min"].as_f64(), p["allowed"]["max"].as_f64()),
        (Some(1.0), Some(159.0))
    );
    s.get(&format!("{DEV}/abc")).await.problem(400);
    s.get(&format!("{DEV}/1?fresh=maybe")).await.problem(400);
    s.get("/api/v1/buses/fake/frames?limit=0")
        .await
        .problem(422);
    s.call(reqwest::Method::DELETE, "/api/v1/buses", None)
        .await
        .problem(405);
    // Body problems: not JSON, wrong shape, unknown field, wrong media type.
    let raw = s
        .client
        .put(format!("{}{DEV}/1/target", s.base))
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_eq!(raw.status(), 400);
    s.put(&format!("{DEV}/1/target"), json!({"position_deg": "ten"}))
        .await
        .problem(422);
    s.put(
        &format!("{DEV}/1/target"),
        json!({"position_deg": 1, "torque": 3}),
    )
    .await
    .problem(422);
    let plain = s
        .client
        .put(format!("{}{DEV}/1/target", s.base))
        .body("{}")
        .send()
        .await
        .unwrap();
    assert_eq!(plain.status(), 415);
    s.put("/api/v1/buses/fake/baud", json!({"baud": 12345}))
        .await
        .problem(422);
    s.post("/api/v1/buses/fake/scan", json!({"first": 10, "last": 2}))
        .await
        .problem(422);
}

#[tokio::test]
async fn targets_need_an_enabled_joint_and_respect_soft_limits() {
    let (bus, s) = setup(None).await;
    let p = s
        .put(&format!("{DEV}/2/target"), json!({"position_deg": 10}))
        .await;
    assert!(p.problem(409)["detail"]
        .as_str()
        .unwrap()
        .contains("enable it first"));
    s.post_empty(&format!("{DEV}/2/enable")).await.ok();
    let r = s
        .put(&format!("{DEV}/2/target"), json!({"position_deg": 120}))
        .await;
    let p = r.problem(422);
    assert_eq!(p["type"], "urn:jointd:problem:soft-limit");
    assert_eq!(p["field"], "position_deg");
    assert_eq!(p["allowed"]["max"], 90.0);
    let p = s
        .put(
            &format!("{DEV}/2/target"),
            json!({"position_deg": 10, "speed_dps": 50}),
        )
        .await;
    assert_eq!(p.problem(422)["allowed"]["max"], 40.0);
    assert!(
        bus.handle.shared().setpoints.get(2).is_none(),
        "a refused target is not stored"
    );
    // Within limits: stored raw (Q7 degrees; Q15 of 50000 rotor rpm for
    // firmware 1.2.8, and 30 °/s at the output is 2844 rotor rpm).
    let r = s
        .put(
            &format!("{DEV}/2/target"),
            json!({"position_deg": 45.5, "speed_dps": 30}),
        )
        .await;
    let body = r.ok();
    assert_eq!(body["targets"][0]["pos_ref_raw"], 5824);
    let stored = bus.handle.shared().setpoints.get(2).expect("stored");
    assert_eq!(
        (stored.setpoint.pos_ref, stored.setpoint.spd_ref),
        (5824, 1864)
    );
    // Joint 1 has no soft limits, only the device range.
    s.post_empty(&format!("{DEV}/1/enable")).await.ok();
    let r = s
        .put(&format!("{DEV}/1/target"), json!({"position_deg": 300}))
        .await;
    let p = r.problem(422);
    assert_eq!(p["allowed"]["max"], 255.0);
    assert_eq!(p["type"], "urn:jointd:problem:out-of-range");
}

#[tokio::test]
async fn group_targets_are_all_or_nothing() {
    let (bus, s) = setup(None).await;
    s.post("/api/v1/buses/fake/control/enable", json!({}))
        .await
        .ok();
    let bad = json!({"targets": [{"id": 1, "position_deg": 10}, {"id": 2, "position_deg": -100}]});
    let r = s.put("/api/v1/buses/fake/control/targets", bad).await;
    assert_eq!(r.problem(422)["field"], "targets[1].position_deg");
    assert!(bus.handle.shared().setpoints.get(1).is_none());
    let good = json!({"targets": [{"id": 1, "position_deg": 10}, {"id": 2, "position_deg": -10}]});
    let r = s.put("/api/v1/buses/fake/control/targets", good).await;
    let seq = r.ok()["seq"].as_u64().unwrap();
    let (a, b) = (
        bus.handle.shared().setpoints.get(1).unwrap(),
        bus.handle.shared().setpoints.get(2).unwrap(),
    );
    assert_eq!((a.seq, b.seq), (seq, seq), "one write for the whole group");
    s.put("/api/v1/buses/fake/control/targets", json!({"targets": []}))
        .await
        .problem(422);
    s.post("/api/v1/buses/fake/control/disable", json!({"ids": [7]}))
        .await
        .problem(404);
}

#[tokio::test]
async fn jog_while_disabled_is_409_and_works_once_enabled() {
    let (bus, s) = setup(None).await;
    s.post(&format!("{DEV}/3/jog"), json!({"direction": "cw"}))
        .await
        .problem(409);
    assert!(!bus.script().log.contains(&"jog"));
    s.post_empty(&format!("{DEV}/3/enable")).await.ok();
    let r = s
        .post(&format!("{DEV}/3/jog"), json!({"direction": "ccw"}))
        .await;
    assert_eq!(r.ok()["value"], "ccw");
    s.post(&format!("{DEV}/3/jog"), json!({"direction": "up"}))
        .await
        .problem(422);
}

#[tokio::test]
async fn silent_device_is_504_and_down_bus_is_503() {
    let (bus, s) = setup(None).await;
    bus.script().silent.insert(1);
    s.get(&format!("{DEV}/1?fresh=true")).await.problem(504);
    s.get(&format!("{DEV}/1/config")).await.problem(504);
    s.get(&format!("{DEV}/2?fresh=true")).await.ok();
    bus.script().down = true;
    s.post_empty(&format!("{DEV}/2/enable")).await.problem(503);
    s.post("/api/v1/buses/fake/scan", json!({"first": 1, "last": 16}))
        .await
        .problem(503);
}

#[tokio::test]
async fn config_reads_in_physical_units_and_writes_are_checked_first() {
    let (bus, s) = setup(None).await;
    let c = s.get(&format!("{DEV}/1/config")).await;
    let c = c.ok();
    assert_eq!(c["max_current_a"]["raw"], 4368);
    assert!((c["max_current_a"]["value"].as_f64().unwrap() - 0.7498).abs() < 1e-3);
    assert_eq!(c["protect_delay_ms"]["value"], 600.0);
    assert_eq!(c["burst_cold_ms"]["value"], 100.0);
    assert_eq!(c["baud"], 500000);
    let r = s
        .patch(
            &format!("{DEV}/1/config"),
            json!({"pos_kp": 1.0, "lpf_level": 6}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "lpf_level");
    assert!(
        !bus.script().log.contains(&"write_config"),
        "nothing written when one value is bad"
    );
    let r = s
        .patch(
            &format!("{DEV}/1/config"),
            json!({"pos_kp": 1.25, "max_current_a": 2.0}),
        )
        .await;
    let w = &r.ok()["written"];
    assert_eq!(
        (w[0]["param"].as_str(), w[0]["raw"].as_u64()),
        (Some("pos_kp"), Some(5120))
    );
    assert_eq!(
        (w[1]["index"].as_u64(), w[1]["raw"].as_u64()),
        (Some(18), Some(11650))
    );
    bus.script().mismatch = true;
    let r = s
        .patch(&format!("{DEV}/1/config"), json!({"spd_ki": 0.5}))
        .await;
    assert_eq!(r.problem(502)["field"], "spd_ki");
    let r = s.post_empty(&format!("{DEV}/1/config/persist")).await;
    assert_eq!(r.ok()["verified_by"], "res");
}

/// A PATCH that did not confirm everything lists every parameter as
/// written, unverified or not written: an unverified one does not stop the
/// rest (504 when nothing else failed); any other failure does, and gives
/// the status.
#[tokio::test]
async fn a_patch_reports_written_unverified_and_not_written() {
    let (bus, s) = setup(None).await;
    bus.script().unverified_at.insert(18);
    let all = json!({"pos_kp": 1.25, "max_current_a": 2.0, "burst_plus_ms": 100.0});
    let r = s.patch(&format!("{DEV}/1/config"), all.clone()).await;
    let p = r.problem(504);
    assert_eq!(p["type"], "urn:jointd:problem:write-unverified", "{p}");
    assert_eq!(p["field"], "max_current_a");
    let keys = |list: &str| -> Vec<String> {
        let items = p["partial"][list].as_array().unwrap();
        items
            .iter()
            .map(|w| w["param"].as_str().unwrap().to_owned())
            .collect()
    };
    assert_eq!(keys("written"), ["pos_kp", "burst_plus_ms"]);
    assert_eq!(keys("unverified"), ["max_current_a"]);
    assert!(keys("not_written").is_empty());
    assert_eq!(p["partial"]["unverified"][0]["raw"], 11650);

    // pos_kp unverified, max_current_a read back otherwise: that stops the
    // PATCH (502) and burst_plus_ms is never sent.
    bus.script().unverified_at = [8].into();
    bus.script().mismatch_at.insert(18);
    let r = s.patch(&format!("{DEV}/1/config"), all).await;
    let p = r.problem(502);
    assert_eq!(p["type"], "urn:jointd:problem:verify-mismatch", "{p}");
    assert_eq!(p["field"], "max_current_a");
    let list = |name: &str| p["partial"][name].as_array().unwrap().clone();
    assert!(list("written").is_empty());
    assert_eq!(list("unverified")[0]["param"], "pos_kp");
    let not_written = list("not_written");
    assert_eq!(not_written[0]["param"], "max_current_a");
    assert_eq!(not_written[1]["param"], "burst_plus_ms");
    assert!(not_written[1]["reason"]
        .as_str()
        .unwrap()
        .contains("not sent"));

    // A flash write whose RES was lost is unverified, not "not persisted".
    bus.script().unverified_at.insert(13);
    let r = s.post_empty(&format!("{DEV}/1/config/persist")).await;
    assert_eq!(
        r.problem(504)["type"],
        "urn:jointd:problem:write-unverified"
    );
}

/// A device that answers something other than what was asked is the
/// device's failure: 502 `unexpected-reply` on every route, whether the
/// handler or the bus owner noticed.
#[tokio::test]
async fn a_wrong_reply_is_the_same_502_on_every_route() {
    let (bus, s) = setup(None).await;
    bus.script().wrong_block = true;
    let calls = [
        s.get(&format!("{DEV}/1?fresh=true")).await,
        s.get(&format!("{DEV}/1/config")).await,
        s.post_empty(&format!("{DEV}/1/config/persist")).await,
    ];
    for r in &calls {
        let p = r.problem(502);
        assert_eq!(p["type"], "urn:jointd:problem:unexpected-reply", "{p}");
    }
}

#[tokio::test]
async fn id_change_refuses_a_taken_id() {
    let (_bus, s) = setup(None).await;
    let r = s.put(&format!("{DEV}/1/id"), json!({"new_id": 2})).await;
    assert_eq!(r.problem(409)["field"], "new_id");
    s.put(&format!("{DEV}/1/id"), json!({"new_id": 0}))
        .await
        .problem(422);
    s.put(&format!("{DEV}/1/id"), json!({"new_id": 7}))
        .await
        .ok();
    s.get(&format!("{DEV}/7")).await.ok();
    s.get(&format!("{DEV}/1")).await.problem(404);
}

#[tokio::test]
async fn estop_preempts_queued_requests() {
    let (bus, s) = setup(None).await;
    bus.script().delay = Duration::from_millis(200);
    let busy: Vec<_> = (0..3)
        .map(|_| {
            let (base, client) = (s.base.clone(), s.client.clone());
            tokio::spawn(async move {
                client
                    .post(format!("{base}/api/v1/buses/fake/scan"))
                    .json(&json!({"first": 1, "last": 3}))
                    .send()
                    .await
                    .unwrap()
                    .status()
            })
        })
        .collect();
    // Stop once all three are with the bus (the fake owner never takes one
    // off this count): one being served, two queued behind it. A scan that
    // reached the bus after the e-stop would rightly run after it.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    let sent = || bus.handle.shared().queued.load(Ordering::Relaxed);
    while sent() < 3 && tokio::time::Instant::now() < deadline {
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
    assert_eq!(sent(), 3, "the three scans never reached the bus");
    let r = s.post_empty("/api/v1/estop").await;
    let body = r.ok();
    assert_eq!(body["stopped"], true);
    assert_eq!(body["buses"][0]["frames_sent"], 4);
    let mut statuses = Vec::new();
    for b in busy {
        statuses.push(b.await.unwrap().as_u16());
    }
    assert!(
        statuses.contains(&409),
        "queued work is preempted: {statuses:?}"
    );
    let log = bus.script().log.clone();
    let stop_at = log.iter().position(|k| *k == "estop").unwrap();
    assert!(
        log[stop_at..].iter().all(|k| *k != "scan"),
        "nothing queued ran after the e-stop: {log:?}"
    );
}

#[tokio::test]
async fn metrics_readyz_and_bus_views() {
    let (bus, s) = setup(None).await;
    let m = s.get("/metrics").await;
    let text = m.body.as_str().unwrap();
    assert!(m.content_type.starts_with("text/plain"));
    assert!(text.contains("jointd_bus_up{bus=\"fake\"} 1"), "{text}");
    assert!(text.contains("jointd_bus_frames_rx_total{bus=\"fake\"} 0"));
    for counter in ["verify_retries", "writes_unverified"] {
        let line = format!("jointd_bus_{counter}_total{{bus=\"fake\"}} 0");
        assert!(text.contains(&line), "{line} missing: {text}");
    }
    assert!(text.contains("jointd_device_online{bus=\"fake\",id=\"3\"} 1"));
    assert_eq!(text.matches("# TYPE jointd_device_online gauge").count(), 1);
    s.get("/readyz").await.ok();
    // A wide scan goes to the bus in chunks of 16 ids.
    let found = s
        .post("/api/v1/buses/fake/scan", json!({"first": 1, "last": 40}))
        .await;
    assert_eq!(found.ok()["found"], json!([1, 2, 3]));
    assert_eq!(bus.script().log.iter().filter(|k| **k == "scan").count(), 3);
    let mut snap = (*bus.handle.snapshot()).clone();
    snap.link = jointd::bus::handle::LinkState::Down {
        reason: "unplugged".into(),
        retry_in_ms: 500,
    };
    bus.handle
        .shared()
        .snapshot
        .send_replace(std::sync::Arc::new(snap));
    s.get("/readyz").await.problem(503);
    let v = s.get("/api/v1/buses/fake").await;
    assert_eq!(v.ok()["link"], "down");
    assert_eq!(v.body["down_reason"], "unplugged");
    s.put("/api/v1/buses/fake/baud", json!({"baud": 115200}))
        .await
        .ok();
    assert_eq!(bus.handle.snapshot().baud, 115200);
}

#[tokio::test]
async fn path_ids_must_be_plain_decimal() {
    let (_bus, s) = setup(None).await;
    for id in ["+1", "01", "001", "1.0", "%2B1", "-01"] {
        let r = s.get(&format!("{DEV}/{id}")).await;
        assert!(
            r.problem(400)["detail"]
                .as_str()
                .unwrap()
                .contains("plain decimal")
                || id == "1.0",
            "{id}: {}",
            r.body
        );
        s.post_empty(&format!("{DEV}/{id}/enable"))
            .await
            .problem(400);
    }
    s.get(&format!("{DEV}/1")).await.ok();
    s.get(&format!("{DEV}/-1")).await.problem(422);
    s.get(&format!("{DEV}/0")).await.problem(422);
}

#[tokio::test]
async fn a_group_call_naming_a_joint_twice_is_422() {
    let (bus, s) = setup(None).await;
    let p = s
        .post("/api/v1/buses/fake/control/enable", json!({"ids": [1, 1]}))
        .await;
    assert_eq!(p.problem(422)["field"], "ids[1]");
    s.post(
        "/api/v1/buses/fake/control/disable",
        json!({"ids": [2, 3, 2]}),
    )
    .await
    .problem(422);
    s.put(
        "/api/v1/buses/fake/control/mode",
        json!({"ids": [3, 3], "mode": "speed"}),
    )
    .await
    .problem(422);
    let p = s
        .put(
            "/api/v1/buses/fake/control/targets",
            json!({"targets": [{"id": 1, "position_deg": 1.0}, {"id": 1, "position_deg": 2.0}]}),
        )
        .await;
    assert_eq!(p.problem(422)["field"], "targets[1].id");
    assert!(bus.script().log.is_empty(), "{:?}", bus.script().log);
    s.post("/api/v1/buses/fake/control/enable", json!({"ids": [1, 2]}))
        .await
        .ok();
}

#[tokio::test]
async fn a_body_over_the_limit_is_413() {
    let (_bus, s) = setup(None).await;
    // Declared in Content-Length: refused before it is read.
    let big = format!(
        "{{\"targets\": [{}]}}",
        vec![r#"{"id": 1}"#; 120_000].join(",")
    );
    assert!(big.len() > 1024 * 1024);
    let r = s
        .browser(
            reqwest::Method::PUT,
            "/api/v1/buses/fake/control/targets",
            &[("content-type", "application/json")],
            Some(&big),
        )
        .await;
    assert_eq!(r.problem(413)["type"], "urn:jointd:problem:body-too-large");
    // Chunked, no length: refused while it is read (axum's body limit).
    let chunk = "x".repeat(64 * 1024);
    let mut req = format!(
        "PUT /api/v1/buses/fake/control/targets HTTP/1.1\r\nHost: {}\r\n\
         Content-Type: application/json\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n",
        s.authority()
    )
    .into_bytes();
    for _ in 0..20 {
        req.extend(format!("{:x}\r\n{chunk}\r\n", chunk.len()).into_bytes());
    }
    req.extend(b"0\r\n\r\n");
    let (status, text) = support::http::raw(s.authority(), &req).await;
    assert_eq!(status, 413, "{text}");
    assert!(text.contains("application/problem+json"), "{text}");
}

#[tokio::test]
async fn the_body_limit_is_configurable() {
    let bus = FakeBus::new("fake", &[1, 2, 3]);
    let state = AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            limits(),
        )),
        None,
    );
    let mut options = jointd::http::state::HttpOptions::default();
    options.policy.max_body_bytes = 64;
    assert!(state.set_options(options).is_ok());
    let s = serve(state).await;
    let body = json!({"targets": [{"id": 1, "position_deg": 1.0}, {"id": 2, "position_deg": 1.0}]});
    assert!(body.to_string().len() > 64);
    s.put("/api/v1/buses/fake/control/targets", body)
        .await
        .problem(413);
    s.post("/api/v1/buses/fake/control/enable", json!({"ids": [1]}))
        .await
        .ok();
}

#[tokio::test]
async fn a_plain_get_of_the_websocket_endpoint_is_426() {
    let (_bus, s) = setup(None).await;
    let r = s.get("/api/v1/ws").await;
    assert_eq!(
        r.problem(426)["type"],
        "urn:jointd:problem:upgrade-required"
    );
    assert_eq!(r.headers["upgrade"], "websocket");
    // With a token, the token is asked for first.
    let (_bus, s) = setup(Some("t")).await;
    s.get("/api/v1/ws").await.problem(401);
    s.with_token("t").get("/api/v1/ws").await.problem(426);
}
