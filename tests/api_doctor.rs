//! `POST /api/v1/buses/{bus}/doctor`: the doctor's report on a configured
//! bus, run on the port its owner lends. It sends only reads and the bus
//! polls again after it; it is refused while a joint is enabled; an e-stop
//! stops it at its next frame and runs at once. Assertions are on what
//! reached the simulated wire and on the report, never on timings.

mod support;

use jointd::protocol::{Command, ConfigParam, ControlOp, Frame};
use serde_json::Value;
use support::sim_bus::{start, SimBus, BUS, WAIT};

const DOCTOR: &str = "/api/v1/buses/sim0/doctor";

fn check<'a>(report: &'a Value, id: &str) -> Option<&'a Value> {
    report["checks"].as_array()?.iter().find(|c| c["id"] == id)
}

/// Every host frame the simulator saw is a read of an INFO block, or,
/// with `disables`, an e-stop's disable.
fn only_reads(b: &SimBus, disables: bool) {
    for f in b.sim.frame_log().iter().filter(|f| f.from_host) {
        let cmd = Frame::decode(&f.bytes)
            .ok()
            .and_then(|fr| Command::from_frame(&fr).ok());
        assert!(
            match cmd {
                Some(Command::Config(c)) => matches!(c.param, ConfigParam::ReadInfo(_)),
                Some(Command::Control(c)) => disables && c.op == ControlOp::Disable,
                _ => false,
            },
            "a frame that is no read reached the wire: {cmd:?}"
        );
    }
}

async fn polls(b: &SimBus) -> u64 {
    b.handle.snapshot().counters.polls
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_doctor_checks_a_running_bus_with_reads_only_and_polling_resumes() {
    let b = start(4, None).await;
    b.sim.clear_frame_log();
    let r = b.server.post_empty(DOCTOR).await;
    assert_eq!(r.status, 200, "{}", r.body);
    let report = &r.body;
    let open = check(report, "open").expect("the open check");
    assert!(
        open["found"]
            .as_str()
            .is_some_and(|s| s.contains("lent by bus sim0")),
        "{open}"
    );
    let found: Vec<u64> = report["devices"]
        .as_array()
        .expect("devices")
        .iter()
        .filter_map(|d| d["id"].as_u64())
        .collect();
    assert_eq!(found, vec![1, 2, 3, 4], "{report}");
    assert_eq!(report["proposal"]["config"]["baud"], 500_000, "{report}");
    only_reads(&b, false);
    assert!(b.sim.devices().iter().all(|d| !d.enabled));
    let after = polls(&b).await;
    b.wait_snapshot("polling again after the run", |s| {
        s.counters.polls > after + 8 && s.devices.values().all(|d| d.online)
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_enabled_joint_refuses_the_doctor_and_nothing_is_sent() {
    let b = start(2, None).await;
    let r = b
        .server
        .post_empty(&format!("/api/v1/buses/{BUS}/devices/1/enable"))
        .await;
    assert!(r.status.is_success(), "{}", r.body);
    b.sim.clear_frame_log();
    let r = b.server.post_empty(DOCTOR).await;
    assert_eq!(r.status, 409, "{}", r.body);
    let detail = r.body["detail"].as_str().unwrap_or_default();
    assert!(detail.contains("enabled"), "{}", r.body);
    // The bus's own polls only: no scan of the absent ids 3..
    for f in b.sim.frame_log().iter().filter(|f| f.from_host) {
        assert!(f.dev_id.is_none_or(|id| id <= 2), "{f:?}");
    }
    assert!(b.sim.device(1).is_some_and(|d| d.enabled));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_stops_the_doctor_at_its_next_frame() {
    let b = start(2, None).await;
    b.sim.clear_frame_log();
    let server = support::http::Server {
        base: b.server.base.clone(),
        client: b.server.client.clone(),
        token: b.server.token.clone(),
    };
    let run = tokio::spawn(async move { server.post_empty(DOCTOR).await });
    // The doctor's scan reaches ids the bus never polls.
    let deadline = std::time::Instant::now() + WAIT;
    while !b
        .sim
        .frame_log()
        .iter()
        .any(|f| f.from_host && f.dev_id.is_some_and(|id| id > 2))
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the doctor never scanned"
        );
        tokio::time::sleep(std::time::Duration::from_millis(2)).await;
    }
    let estop = b.handle.estop().await.expect("e-stop");
    assert!(estop.still_enabled.is_empty(), "{estop:?}");
    let r = run.await.expect("the doctor's call");
    assert_eq!(r.status, 200, "{}", r.body);
    let stopped = r.body["checks"].as_array().and_then(|checks| {
        checks.iter().find(|c| {
            c["verdict"] == "fail" && c["found"].as_str().is_some_and(|s| s.contains("e-stop"))
        })
    });
    assert!(stopped.is_some(), "{}", r.body);
    // Cut short: the bursts of the devices never ran.
    assert_eq!(r.body["devices"].as_array().map(Vec::len), Some(0));
    only_reads(&b, true);
}

/// Waits until the doctor's scan reached an id above `known` (ids the bus
/// itself never polls): the port is lent.
async fn lent(b: &SimBus, known: u8) {
    let deadline = std::time::Instant::now() + WAIT;
    while !b
        .sim
        .frame_log()
        .iter()
        .any(|f| f.from_host && f.dev_id.is_some_and(|id| id > known))
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the doctor never scanned"
        );
        tokio::time::sleep(std::time::Duration::from_millis(2)).await;
    }
}

fn client_of(b: &SimBus) -> support::http::Server {
    support::http::Server {
        base: b.server.base.clone(),
        client: b.server.client.clone(),
        token: b.server.token.clone(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_check_while_one_runs_is_refused() {
    let b = start(2, None).await;
    b.sim.clear_frame_log();
    let server = client_of(&b);
    let first = tokio::spawn(async move { server.post_empty(DOCTOR).await });
    lent(&b, 2).await;
    let second = b.server.post_empty(DOCTOR).await;
    assert_eq!(second.status, 409, "{}", second.body);
    assert!(
        second.body["detail"]
            .as_str()
            .is_some_and(|d| d.contains("being checked already")),
        "{}",
        second.body
    );
    let first = first.await.expect("the first call");
    assert_eq!(first.status, 200, "{}", first.body);
    // Once it ended, another may run.
    let again = b.server.post_empty(DOCTOR).await;
    assert_eq!(again.status, 200, "{}", again.body);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stopping_the_bus_stops_the_check_and_the_owner_ends() {
    let mut b = start(2, None).await;
    b.sim.clear_frame_log();
    let server = client_of(&b);
    let run = tokio::spawn(async move { server.post_empty(DOCTOR).await });
    lent(&b, 2).await;
    let thread = b.thread.take().expect("the bus thread");
    tokio::task::spawn_blocking(move || thread.stop())
        .await
        .expect("the owner stopped");
    let r = run.await.expect("the doctor's call");
    assert_eq!(r.status, 200, "{}", r.body);
    let stopped = r.body["checks"].as_array().and_then(|checks| {
        checks.iter().find(|c| {
            c["verdict"] == "fail" && c["found"].as_str().is_some_and(|s| s.contains("stopping"))
        })
    });
    assert!(stopped.is_some(), "{}", r.body);
}
