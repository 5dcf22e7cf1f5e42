//! Every generated path starts where the joint is, never from a target
//! it has not reached: a joint on its way to one target, given a move the
//! other way, never turns towards the first target on the way. Sampled on
//! the simulated device itself, at every turn of the test's loop.

mod support;

use std::time::Duration;

use jointd::protocol::status::fsm;
use serde_json::json;
use support::sim_bus::{start, SimBus, WAIT};

/// The simulated joint's angle, as the device has it.
fn angle(b: &SimBus, id: u8) -> f64 {
    b.sim.device(id).expect("a device").angle_deg
}

async fn wait_angle(b: &SimBus, id: u8, what: &str, pred: impl Fn(f64) -> bool) -> f64 {
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let a = angle(b, id);
        if pred(a) {
            return a;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "timed out: {what} (at {a}°)"
        );
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_move_the_other_way_from_a_slow_target_never_turns_towards_it() {
    let b = start(2, None).await;
    b.server
        .post("/api/v1/buses/sim0/devices/1/enable", json!({}))
        .await
        .ok();
    b.wait_fsm(1, fsm::RUN).await;
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 80, "speed_dps": 10}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 200, "{}", r.body);
    // On its slow way up, well short of 80°.
    wait_angle(&b, 1, "the joint on its way up", |a| a > 3.0).await;
    let stood = angle(&b, 1);
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": -10}], "duration_ms": 800}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
    let id = r.body["id"].as_u64().expect("an id");
    // Between where it stood when the move was admitted and the goal, all
    // the way (2° for the sample the path started from being a little old).
    let mut highest = stood;
    let deadline = tokio::time::Instant::now() + WAIT;
    loop {
        let a = angle(&b, 1);
        highest = highest.max(a);
        if a < -9.0 {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the move never arrived (at {a}°)"
        );
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    assert!(
        highest <= stood + 2.0,
        "the joint turned up to {highest:.1}° from {stood:.1}° on a move to -10°"
    );
    let done = b
        .wait_move(id, "the move done", |v| v["state"] == "done")
        .await;
    assert_eq!(done["arrived"].as_array().map(Vec::len), Some(1), "{done}");
}
