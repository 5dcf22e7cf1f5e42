//! A grasp is a motion under the motion authority: an e-stop while the
//! fingers close and while they hold stops every finger (each `aborted`,
//! the joints disabled, no finger moves on), a disable ends the finger it
//! disables, and every limit is written back and read back however the
//! grasp ended.

mod grasp_rig;
mod support;

use grasp_rig::{finger, grasp, hand, limits_restored, state_of, wait_grasp, FACTORY_MAX_CUR};
use serde_json::{json, Value};
use support::sim_bus::SimBus;

/// Every finger is `aborted` for an e-stop, its joint disabled.
async fn all_aborted_by_estop(b: &SimBus, id: u64) -> Value {
    let view = wait_grasp(b, id, "every finger aborted", |v| v["state"] == "done").await;
    for f in view["fingers"].as_array().expect("fingers") {
        assert_eq!(f["state"], "aborted", "{view}");
        assert_eq!(f["reason"], "e-stop", "{view}");
        let dev = b
            .sim
            .device(f["id"].as_u64().expect("id") as u8)
            .expect("device");
        assert!(!dev.enabled, "joint {} still enabled", dev.id);
    }
    view
}

/// No simulated joint moves any more (checked over a few hundred polls).
async fn nothing_moves(b: &SimBus) {
    let before: Vec<f64> = (1..=3)
        .map(|id| b.sim.device(id).expect("d").angle_deg)
        .collect();
    let start = b.handle.snapshot().counters.polls;
    b.wait_snapshot("the owner polling on", |s| s.counters.polls >= start + 200)
        .await;
    for (k, id) in (1..=3).enumerate() {
        let now = b.sim.device(id).expect("d").angle_deg;
        assert!(
            (now - before[k]).abs() < 0.5,
            "joint {id} moved from {} to {now}",
            before[k]
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_while_the_fingers_close_stops_every_finger() {
    let b = hand(&[(1, 35.0, 0.05)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 20.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 40.0}, {"joint": "b", "close_to_deg": 40.0},
            {"joint": "c", "close_to_deg": 40.0}]}),
    )
    .await;
    wait_grasp(&b, id, "every finger closing and under way", |v| {
        ["a", "b", "c"].iter().all(|j| state_of(v, j) == "closing")
            && (1..=3).all(|id| b.sim.device(id).is_some_and(|d| d.angle_deg > 3.0))
    })
    .await;
    b.server.post_empty("/api/v1/estop").await.ok();
    let view = all_aborted_by_estop(&b, id).await;
    limits_restored(&b, &view).await;
    nothing_moves(&b).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_while_the_fingers_hold_stops_every_finger() {
    let b = hand(&[(1, 10.0, 0.05), (2, 12.0, 0.02), (3, 8.0, 0.1)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 30.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 40.0}, {"joint": "b", "close_to_deg": 40.0},
            {"joint": "c", "close_to_deg": 40.0}]}),
    )
    .await;
    wait_grasp(&b, id, "every finger holding", |v| {
        ["a", "b", "c"].iter().all(|j| state_of(v, j) == "holding")
    })
    .await;
    b.server.post_empty("/api/v1/estop").await.ok();
    let view = all_aborted_by_estop(&b, id).await;
    for j in ["a", "b", "c"] {
        assert_eq!(finger(&view, j)["contact"], true);
    }
    limits_restored(&b, &view).await;
    nothing_moves(&b).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_disable_ends_its_finger_and_the_others_hold_on() {
    let b = hand(&[(1, 10.0, 0.05), (2, 10.0, 0.05)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 30.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 40.0}, {"joint": "b", "close_to_deg": 40.0}]}),
    )
    .await;
    wait_grasp(&b, id, "a and b holding", |v| {
        state_of(v, "a") == "holding" && state_of(v, "b") == "holding"
    })
    .await;
    b.server
        .post("/api/v1/buses/sim0/control/disable", json!({"ids": [1]}))
        .await
        .ok();
    let view = wait_grasp(&b, id, "a aborted", |v| state_of(v, "a") == "aborted").await;
    let a = finger(&view, "a");
    assert!(
        a["reason"].as_str().unwrap_or("").contains("disabl")
            || a["reason"].as_str().unwrap_or("").contains("revoked"),
        "{a}"
    );
    assert_eq!(a["current_limit_restored"], true, "{a}");
    assert_eq!(state_of(&view, "b"), "holding", "{view}");
    // A mode change ends the other one.
    b.server
        .put(
            "/api/v1/buses/sim0/devices/2/mode",
            json!({"mode": "speed"}),
        )
        .await
        .ok();
    let view = wait_grasp(&b, id, "done", |v| v["state"] == "done").await;
    assert_eq!(state_of(&view, "b"), "aborted", "{view}");
    limits_restored(&b, &view).await;
}

/// A move that takes a finger out of a holding grasp starts where the
/// finger stands against its object, not from the grasp's closing limit:
/// it never presses further in, though the grasp hands its full current
/// limit back as the move takes over.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_out_of_a_holding_grasp_never_presses_further_in() {
    let b = hand(&[(1, 20.0, 0.01)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 30.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 80.0}]}),
    )
    .await;
    wait_grasp(&b, id, "a holding", |v| state_of(v, "a") == "holding").await;
    let stood = b.sim.device(1).expect("d").angle_deg;
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 0}], "duration_ms": 1000}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
    let mut deepest = stood;
    let deadline = tokio::time::Instant::now() + support::sim_bus::WAIT;
    loop {
        let a = b.sim.device(1).expect("d").angle_deg;
        deepest = deepest.max(a);
        if a < 1.0 {
            break;
        }
        if tokio::time::Instant::now() >= deadline {
            let mid = r.body["id"].as_u64().unwrap_or(0);
            let mv = b.server.get(&format!("/api/v1/moves/{mid}")).await;
            let g = b.server.get(&format!("/api/v1/grasps/{id}")).await;
            panic!(
                "never opened (at {a}°): moves {} grasp {} stood {stood}",
                mv.body, g.body
            );
        }
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
    assert!(
        deepest <= stood + 2.0,
        "the finger pressed on to {deepest:.1}° from {stood:.1}° before opening"
    );
    let view = wait_grasp(&b, id, "done", |v| v["state"] == "done").await;
    assert_eq!(finger(&view, "a")["current_limit_restored"], true, "{view}");
}

/// A short bus unplug while the fingers hold: each finger ends (the joint
/// went offline) with its lowered limit owed; once the bus is back the
/// limit is written and read back, the finger's view and the joint's say
/// so, and nothing moved the joint meanwhile: a move while owed is 409.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_limit_lost_to_an_unplug_is_owed_and_written_back_once_the_bus_is_back() {
    let b = hand(&[(1, 10.0, 0.05), (2, 12.0, 0.05)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 30.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 40.0}, {"joint": "b", "close_to_deg": 40.0}]}),
    )
    .await;
    wait_grasp(&b, id, "both holding", |v| {
        state_of(v, "a") == "holding" && state_of(v, "b") == "holding"
    })
    .await;
    b.sim.inject(jointd::sim::Fault::Unplug);
    let view = wait_grasp(&b, id, "every finger ended", |v| v["state"] == "done").await;
    for j in ["a", "b"] {
        assert_eq!(finger(&view, j)["state"], "aborted", "{view}");
        assert_eq!(finger(&view, j)["current_limit_restored"], false, "{view}");
    }
    // Owed while the joints cannot be reached: said on the joint's view
    // and in the metrics, and no new motion of the joint is admitted.
    let dev = b.server.get("/api/v1/buses/sim0/devices/1").await;
    assert!(
        dev.ok()["current_limit_owed_a"]
            .as_f64()
            .is_some_and(|a| a > 0.2),
        "{}",
        dev.body
    );
    let metrics = b.server.get("/metrics").await;
    let text = metrics.body.as_str().unwrap_or_default();
    assert!(
        text.contains("jointd_bus_current_limits_owed{bus=\"sim0\"} 2"),
        "{text}"
    );
    b.sim.inject(jointd::sim::Fault::Replug);
    // Written and read back once the joints answer: the fingers say so,
    // and the device holds its own limit again.
    let view = wait_grasp(&b, id, "both limits back", |v| {
        ["a", "b"]
            .iter()
            .all(|j| finger(v, j)["current_limit_restored"] == true)
    })
    .await;
    limits_restored(&b, &view).await;
    let dev = b.server.get("/api/v1/buses/sim0/devices/1").await;
    assert!(dev.ok()["current_limit_owed_a"].is_null(), "{}", dev.body);
}

/// While a limit is owed every new motion of the joint is refused, naming
/// why: a move, a grasp, a target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_new_motion_of_a_joint_owed_its_limit_is_admitted() {
    let b = hand(&[]).await;
    assert!(b.handle.owed_limits().owe(1, FACTORY_MAX_CUR));
    let owed = |r: &support::http::Resp| {
        let p = r.problem(409);
        assert_eq!(p["type"], "urn:jointd:problem:current-limit-owed", "{p}");
    };
    let mv = json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 5}], "duration_ms": 300});
    owed(&b.server.post("/api/v1/moves", mv.clone()).await);
    owed(
        &b.server
            .post(
                "/api/v1/hands/h/grasp",
                json!({"speed_dps": 30, "hold_current_a": 0.2, "joints": [{"joint": "a"}]}),
            )
            .await,
    );
    owed(
        &b.server
            .put(
                "/api/v1/buses/sim0/devices/1/target",
                json!({"position_deg": 5}),
            )
            .await,
    );
    // Joint 2 owes nothing: it moves.
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 2, "position_deg": 5}], "duration_ms": 300}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
    b.handle.owed_limits().settle(1);
    let r = b.server.post("/api/v1/moves", mv).await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
}

/// A finger whose replies stop mid-hold: the grasp ends, its limit cannot
/// be read back and stays owed; once the joint answers again the limit is
/// written and read back, and the finger says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_finger_silent_mid_hold_gets_its_limit_back_once_it_answers() {
    let b = hand(&[(1, 10.0, 0.05)]).await;
    let id = grasp(
        &b,
        json!({"speed_dps": 30.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": 40.0}]}),
    )
    .await;
    wait_grasp(&b, id, "a holding", |v| state_of(v, "a") == "holding").await;
    b.sim.inject(jointd::sim::Fault::DropReplies {
        dev_id: Some(1),
        rate: 1.0,
    });
    let view = wait_grasp(&b, id, "a ended", |v| v["state"] == "done").await;
    assert_eq!(
        finger(&view, "a")["current_limit_restored"],
        false,
        "{view}"
    );
    assert!(b.handle.owed_limits().get(1).is_some());
    b.sim.inject(jointd::sim::Fault::ClearAll);
    let view = wait_grasp(&b, id, "a's limit back", |v| {
        finger(v, "a")["current_limit_restored"] == true
    })
    .await;
    limits_restored(&b, &view).await;
    assert!(b.handle.owed_limits().get(1).is_none());
}
