//! A release opens: a goal on the closing side of a finger is refused
//! before anything moves, and a stop ends a release still on its way.

mod grasp_rig;
mod support;

use serde_json::json;

use grasp_rig::{finger, grasp, hand, limits_restored, state_of, wait_grasp};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_release_that_would_close_is_refused_and_a_stop_ends_an_opening() {
    // An object before joint 1 at 10°: the finger holds near it.
    let b = hand(&[(1, 10.0, 0.1)]).await;
    let s = &b.server;
    let id = grasp(
        &b,
        json!({"speed_dps": 30, "hold_current_a": 0.2,
               "joints": [{"joint": "a", "close_to_deg": 30}]}),
    )
    .await;
    wait_grasp(&b, id, "a holding", |v| state_of(v, "a") == "holding").await;

    // A pose further closed than the finger stands is no release.
    s.put(
        "/api/v1/hands/h/poses/tighter",
        json!({"positions_deg": {"a": 25.0, "b": 0.0, "c": 0.0}}),
    )
    .await
    .ok();
    let r = s
        .post(
            &format!("/api/v1/grasps/{id}/release"),
            json!({"pose": "tighter"}),
        )
        .await;
    let p = r.problem(422);
    assert!(
        p["detail"]
            .as_str()
            .unwrap_or("")
            .contains("a release opens"),
        "{p}"
    );
    assert_eq!(
        state_of(
            &s.get(&format!("/api/v1/grasps/{id}")).await.ok().clone(),
            "a"
        ),
        "holding",
        "nothing moved"
    );

    // Opening by an angle goes away from the object; a stop on its way
    // holds the finger where it is and gives the limit back.
    let held = b.sim.device(1).expect("device").angle_deg;
    let release_path = format!("/api/v1/grasps/{id}/release");
    let release = s.post(&release_path, json!({"open_deg": 8, "speed_dps": 1}));
    let stop = async {
        wait_grasp(&b, id, "a opening", |v| state_of(v, "a") == "releasing").await;
        s.post_empty(&format!("/api/v1/grasps/{id}/stop")).await
    };
    let (_, stopped) = tokio::join!(release, stop);
    let view = stopped.ok().clone();
    let a = finger(&view, "a");
    assert_eq!(a["state"], "stopped", "{view}");
    assert!(
        a["reason"].as_str().unwrap_or("").contains("while opening"),
        "{view}"
    );
    let angle = b.sim.device(1).expect("device").angle_deg;
    assert!(
        angle <= held + 0.5,
        "opened the other way: {angle}° from {held}°"
    );
    limits_restored(&b, &view).await;
}

/// A release's speed is checked as every motion speed is: over a finger's
/// soft speed limit it is refused before anything moves.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_release_faster_than_a_fingers_soft_limit_is_refused() {
    // Joint b (id 2) may turn at 60 °/s at most.
    let b = hand(&[(2, 10.0, 0.1)]).await;
    let s = &b.server;
    let id = grasp(
        &b,
        json!({"speed_dps": 30, "hold_current_a": 0.2,
               "joints": [{"joint": "b", "close_to_deg": 30}]}),
    )
    .await;
    wait_grasp(&b, id, "b holding", |v| state_of(v, "b") == "holding").await;
    let r = s
        .post(
            &format!("/api/v1/grasps/{id}/release"),
            json!({"open_deg": 5, "speed_dps": 180}),
        )
        .await;
    let p = r.problem(422);
    assert_eq!(p["type"], "urn:jointd:problem:soft-limit", "{p}");
    let view = s.get(&format!("/api/v1/grasps/{id}")).await.ok().clone();
    assert_eq!(state_of(&view, "b"), "holding", "nothing moved: {view}");
    let r = s
        .post(
            &format!("/api/v1/grasps/{id}/release"),
            json!({"open_deg": 5, "speed_dps": 1e-300}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "speed_dps", "{}", r.body);
    let view = s
        .post(
            &format!("/api/v1/grasps/{id}/release"),
            json!({"open_deg": 5, "speed_dps": 40}),
        )
        .await
        .ok()
        .clone();
    assert_eq!(state_of(&view, "b"), "released", "{view}");
    limits_restored(&b, &view).await;
}
