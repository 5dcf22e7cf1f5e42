//! What recordings hear of the targets: every write to a bus's setpoint
//! store, whoever made it, with its source. A move's samples (one write
//! per control cycle, source `move` with its id) are time-ordered and end
//! with the move's goal exactly; a REST setpoint says `rest`.

mod support;

use jointd::bus::handle::Commanded;
use jointd::bus::Source;
use jointd::protocol::status::fsm;
use jointd::protocol::units;
use serde_json::json;
use support::sim_bus::start;
use tokio::sync::broadcast;

/// Every write the tap still holds.
fn drain(tap: &mut broadcast::Receiver<Commanded>) -> Vec<Commanded> {
    let mut out = Vec::new();
    loop {
        match tap.try_recv() {
            Ok(c) => out.push(c),
            Err(broadcast::error::TryRecvError::Lagged(n)) => panic!("lost {n} writes"),
            Err(_) => return out,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_moves_targets_reach_the_tap_in_order_ending_at_its_goal() {
    let b = start(2, None).await;
    b.server
        .post(
            "/api/v1/buses/sim0/control/enable",
            json!({ "ids": [1, 2] }),
        )
        .await
        .ok();
    b.wait_fsm(1, fsm::RUN).await;
    b.wait_fsm(2, fsm::RUN).await;
    let mut tap = b.handle.shared().setpoints.subscribe();

    // Linear: the path's last sample before its end falls short of the goal.
    let r = b
        .server
        .post(
            "/api/v1/moves",
            json!({"joints": [{"bus": "sim0", "id": 1, "position_deg": 30.0}],
                   "duration_ms": 400, "method": "linear"}),
        )
        .await;
    assert_eq!(r.status.as_u16(), 201, "{}", r.body);
    let move_id = r.body["id"].as_u64().expect("an id");
    b.wait_move(move_id, "the move done", |v| v["state"] == "done")
        .await;
    let r = b
        .server
        .put(
            "/api/v1/buses/sim0/control/targets",
            json!({"targets": [{"id": 2, "position_deg": -5.0}]}),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.body);

    let writes = drain(&mut tap);
    let of_move: Vec<&Commanded> = writes
        .iter()
        .filter(|c| c.source == Source::Move { move_id })
        .collect();
    // Sampled per control cycle: many writes over 400 ms.
    assert!(of_move.len() >= 20, "{} writes of the move", of_move.len());
    for pair in of_move.windows(2) {
        assert!(pair[0].seq < pair[1].seq, "sequence order");
        assert!(pair[0].at <= pair[1].at, "time order");
        let (a, b) = (pair[0].targets[0].1.pos_ref, pair[1].targets[0].1.pos_ref);
        assert!(a <= b, "a path from 0 to 30 never goes back: {a} then {b}");
    }
    assert!(of_move
        .iter()
        .all(|c| c.targets.len() == 1 && c.targets[0].0 == 1));
    let goal = units::angle_to_raw(30.0).expect("in range");
    let last = of_move.last().expect("writes");
    assert_eq!(
        last.targets[0].1.pos_ref, goal,
        "the last target is the goal"
    );
    // The REST setpoint after it: one write, its source said.
    let rest: Vec<&Commanded> = writes.iter().filter(|c| c.source == Source::Rest).collect();
    assert_eq!(rest.len(), 1, "{rest:?}");
    assert_eq!(rest[0].targets[0].0, 2);
    assert!(rest[0].seq > last.seq);
}
