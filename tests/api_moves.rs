//! Moves generated in the daemon, against the simulator: a
//! 16-joint move arrives in the simulator within 0.5° of every target; a
//! path leaving a soft limit is refused whole; a move is stopped, replaced
//! joint by joint, and aborted by an e-stop; bad requests get a 4xx that
//! says what was wrong.

mod support;

use std::time::Duration;

use jointd::bus::handle::BusEvent;
use jointd::protocol::status::fsm;
use jointd::sim::Fault;
use reqwest::Method;
use serde_json::{json, Value};
use support::sim_bus::{start, SimBus, WAIT};

/// Enables `ids` and waits until each runs (aligned).
async fn enable(b: &SimBus, ids: &[u8]) {
    b.server
        .post("/api/v1/buses/sim0/control/enable", json!({ "ids": ids }))
        .await
        .ok();
    for id in ids {
        b.wait_fsm(*id, fsm::RUN).await;
    }
}

fn target(id: u8) -> f64 {
    // Joint 2 has soft limits of ±45° in the fixture.
    if id % 2 == 0 {
        -20.0 - f64::from(id)
    } else {
        15.0 + f64::from(id)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_16_joint_move_arrives_within_half_a_degree_of_every_target() {
    let b = start(16, None).await;
    let ids: Vec<u8> = (1..=16).collect();
    enable(&b, &ids).await;
    let joints: Vec<Value> = ids
        .iter()
        .map(|id| json!({"bus": "sim0", "id": id, "position_deg": target(*id)}))
        .collect();
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": joints, "duration_ms": 1000, "method": "min_jerk"}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
    assert_eq!(r.body["state"], "running");
    assert_eq!(r.body["method"], "min_jerk");
    assert_eq!(r.body["duration_ms"], 1000.0);
    let id = r.body["id"].as_u64().expect("an id");
    let done = b
        .wait_move(id, "the move done", |v| v["state"] == "done")
        .await;
    assert_eq!(done["arrived"].as_array().map(Vec::len), Some(16));
    assert_eq!(done["progress"], 1.0);
    // The simulated joints follow their last setpoints: each settles at its
    // target (the path's end), within 0.5°.
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let off: Vec<(u8, f64)> = ids
            .iter()
            .map(|id| {
                let angle = b.sim.device(*id).expect("a device").angle_deg;
                (*id, angle - target(*id))
            })
            .filter(|(_, err)| err.abs() > 0.5)
            .collect();
        if off.is_empty() {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "joints off their targets: {off:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_path_leaving_a_soft_limit_is_refused_whole_and_bad_requests_say_why() {
    let b = start(2, None).await;
    enable(&b, &[1, 2]).await;
    let s = &b.server;
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 30},
                              {"bus": "sim0", "id": 2, "position_deg": 60}],
                   "duration_ms": 500}),
        )
        .await;
    let p = r.problem(422);
    assert_eq!(p["field"], "joints[1].position_deg");
    assert_eq!(p["allowed"]["max"], 45.0);
    // Nothing started: no move 1, and joint 1 was sent no target.
    s.get("/api/v1/moves/1").await.problem(404);
    let snap = b.handle.snapshot();
    assert!(snap.devices[&1].target_sent.is_none());
    // A waypoint beyond the limit is refused too, even if the end is within.
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 2}],
                   "waypoints": [{"at_ms": 200, "positions_deg": [50]},
                                 {"at_ms": 400, "positions_deg": [0]}]}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "joints[0].position_deg");
    // Neither a duration nor limits.
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 10}]}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "duration_ms");
    // A negative duration, an unknown bus, a joint twice, waypoints out of order.
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 10}], "duration_ms": -5}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "duration_ms");
    s.post(
        "/api/v1/moves",
        json!({"joints": [{"bus": "nope", "id": 1, "position_deg": 10}], "duration_ms": 100}),
    )
    .await
    .problem(404);
    let twice = json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 10},
                                  {"bus": "sim0", "id": 1, "position_deg": 20}], "duration_ms": 100});
    assert_eq!(
        s.post("/api/v1/moves", twice).await.problem(422)["field"],
        "joints[1]"
    );
    let backwards = json!({"joints": [{"bus": "sim0", "id": 1}],
        "waypoints": [{"at_ms": 300, "positions_deg": [5]}, {"at_ms": 200, "positions_deg": [6]}]});
    let r = s.post("/api/v1/moves", backwards).await;
    assert!(r.problem(422)["detail"]
        .as_str()
        .is_some_and(|d| d.contains("not after")));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_is_stopped_replaced_joint_by_joint_and_aborted_by_an_e_stop() {
    let b = start(3, None).await;
    enable(&b, &[1, 2, 3]).await;
    let s = &b.server;
    let long = |a: f64, c: f64| {
        json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": a},
                          {"bus": "sim0", "id": 3, "position_deg": c}],
               "duration_ms": 20000, "method": "linear"})
    };
    // Stopped by its caller.
    let first = s
        .post("/api/v1/moves", long(40.0, -40.0))
        .await
        .ok()
        .clone();
    let first_id = first["id"].as_u64().expect("id");
    let r = s
        .call(Method::DELETE, &format!("/api/v1/moves/{first_id}"), None)
        .await;
    assert_eq!(r.ok()["state"], "stopped");
    assert_eq!(r.body["reason"], "stopped by its caller");

    // A second move; a target on joint 1 takes it out, joint 3 goes on.
    let second = s
        .post("/api/v1/moves", long(-40.0, 40.0))
        .await
        .ok()
        .clone();
    let second_id = second["id"].as_u64().expect("id");
    s.put(
        "/api/v1/buses/sim0/devices/1/target",
        json!({"position_deg": 5.0}),
    )
    .await
    .ok();
    let view = b
        .wait_move(second_id, "joint 1 replaced", |v| {
            v["replaced"].as_array().is_some_and(|r| !r.is_empty())
        })
        .await;
    assert_eq!(view["state"], "running");
    assert_eq!(view["replaced"], json!([{"bus": "sim0", "id": 1}]));

    // A third move on joint 3 takes it from the second, which then has no
    // joint left: done.
    let third = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 3, "position_deg": 0}],
                   "duration_ms": 20000}),
        )
        .await
        .ok()
        .clone();
    assert_eq!(third["took_over_from"], json!([second_id]));
    let second_now = s.get(&format!("/api/v1/moves/{second_id}")).await;
    assert_eq!(second_now.ok()["state"], "done");

    // An e-stop aborts the third at once.
    s.post_empty("/api/v1/estop").await;
    let third_id = third["id"].as_u64().expect("id");
    let view = b
        .wait_move(third_id, "the move aborted", |v| v["state"] == "aborted")
        .await;
    assert_eq!(view["reason"], "estopped");
    s.get("/api/v1/moves/999").await.problem(404);
}

/// The move events of the bus (the WebSocket forwards these as they are),
/// up to and including the first that `last` accepts.
async fn move_events(
    rx: &mut tokio::sync::broadcast::Receiver<BusEvent>,
    last: impl Fn(&BusEvent) -> bool,
) -> Vec<BusEvent> {
    let mut out = Vec::new();
    loop {
        let e = tokio::time::timeout(WAIT, rx.recv())
            .await
            .unwrap_or_else(|_| panic!("no closing event after {out:?}"))
            .expect("events");
        let end = last(&e);
        if matches!(
            e,
            BusEvent::MoveStarted { .. }
                | BusEvent::MoveProgress { .. }
                | BusEvent::MoveDone { .. }
                | BusEvent::MoveStopped { .. }
                | BusEvent::MoveAborted { .. }
        ) {
            out.push(e);
        }
        if end {
            return out;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_says_started_progress_and_done_and_a_silent_joint_aborts_it() {
    let b = start(2, None).await;
    enable(&b, &[1, 2]).await;
    let mut rx = b.handle.events();
    let s = &b.server;
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 10},
                              {"bus": "sim0", "id": 2, "position_deg": -10}],
                   "duration_ms": 400, "method": "trapezoid"}),
        )
        .await;
    let id = r.ok()["id"].as_u64().expect("id");
    let events = move_events(&mut rx, |e| matches!(e, BusEvent::MoveDone { .. })).await;
    assert!(
        matches!(events.first(), Some(BusEvent::MoveStarted { move_id, ids, .. }) if *move_id == id && ids == &vec![1, 2]),
        "{events:?}"
    );
    assert!(
        matches!(events.last(), Some(BusEvent::MoveDone { move_id, .. }) if *move_id == id),
        "{events:?}"
    );
    let progress: Vec<f64> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::MoveProgress { progress, .. } => Some(*progress),
            _ => None,
        })
        .collect();
    assert!(!progress.is_empty(), "{events:?}");
    assert!(progress.windows(2).all(|w| w[0] <= w[1]), "{progress:?}");

    // Joint 2 falls silent mid-move: offline, and the move is aborted.
    let r = s
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": -10},
                              {"bus": "sim0", "id": 2, "position_deg": 10}],
                   "duration_ms": 20000}),
        )
        .await;
    let id = r.ok()["id"].as_u64().expect("id");
    b.sim.inject(Fault::DropReplies {
        dev_id: Some(2),
        rate: 1.0,
    });
    let events = move_events(&mut rx, |e| matches!(e, BusEvent::MoveAborted { .. })).await;
    assert!(
        matches!(events.last(), Some(BusEvent::MoveAborted { move_id, reason, .. })
            if *move_id == id && reason == "joint 2 went offline"),
        "{events:?}"
    );
    let view = s.get(&format!("/api/v1/moves/{id}")).await.ok().clone();
    assert_eq!(view["state"], "aborted");
    assert_eq!(view["reason"], "joint 2 went offline");
}
