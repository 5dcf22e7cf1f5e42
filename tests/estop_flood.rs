//! E-stop beats everything, a flood of requests included: while hundreds
//! of requests run at once (reads, bus writes, recordings, recordings
//! naming one bus a thousand times), an e-stop is answered and its disable
//! frames go out, and SIGTERM still stops the daemon with every joint
//! disabled. Waits end on their event with generous timeouts; what is
//! asserted is counts and outcomes, never how fast.

#[path = "support/daemon.rs"]
mod daemon;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use daemon::{wait_online, Daemon};
use serde_json::{json, Value};

const JOINTS: usize = 8;
/// Clients sending requests back to back while the e-stop is called.
const FLOODERS: usize = 300;
/// Generous: a loaded 2-core machine. The e-stop's own bus wait is 5 s.
const ESTOP_WITHIN: Duration = Duration::from_secs(20);
const WAIT: Duration = Duration::from_secs(30);

/// How many answers the flood's clients had.
#[derive(Default)]
struct Tally {
    answered: AtomicU64,
}

/// One flooding client: GETs and bus writes in turn until `stop`.
async fn flooder(
    client: reqwest::Client,
    base: String,
    i: usize,
    stop: Arc<AtomicBool>,
    tally: Arc<Tally>,
) {
    let mut n = i;
    while !stop.load(Ordering::Relaxed) {
        n += 1;
        let req = match n % 4 {
            0 => client.get(format!("{base}/api/v1/buses/sim0/devices")),
            1 => client.get(format!("{base}/metrics")),
            2 => client
                .post(format!("{base}/api/v1/buses/sim0/control/disable"))
                .json(&json!({})),
            _ => client
                .post(format!("{base}/api/v1/recordings"))
                .json(&json!({})),
        };
        match req.timeout(WAIT).send().await {
            Ok(r) => {
                let _ = r.bytes().await;
                tally.answered.fetch_add(1, Ordering::Relaxed);
            }
            // The daemon is gone (SIGTERM): nothing more to send.
            Err(_) => return,
        }
    }
}

/// The attack: recordings (four naming the bus a thousand times, four plain),
/// then [`FLOODERS`] clients; returns their tasks and the stop flag. What
/// the daemon answers the setup is not asserted: a stalled one answers
/// nothing, and the e-stop or the exit after it is what tells.
async fn flood(
    d: &Daemon,
    tally: &Arc<Tally>,
) -> (Arc<AtomicBool>, Vec<tokio::task::JoinHandle<()>>) {
    let client = reqwest::Client::builder().timeout(WAIT).build().unwrap();
    let names: Vec<&str> = std::iter::repeat("sim0").take(1000).collect();
    for body in [json!({ "buses": names }), json!({})] {
        for _ in 0..4 {
            let r = client
                .post(d.url("/api/v1/recordings"))
                .json(&body)
                .send()
                .await;
            assert!(
                r.map_or(true, |r| r.status() != 500),
                "a recording request panicked"
            );
        }
    }
    let stop = Arc::new(AtomicBool::new(false));
    let tasks = (0..FLOODERS)
        .map(|i| {
            tokio::spawn(flooder(
                reqwest::Client::new(),
                d.base.clone(),
                i,
                stop.clone(),
                tally.clone(),
            ))
        })
        .collect();
    // Under way once a few hundred answers came back (or it is stalled).
    let deadline = tokio::time::Instant::now() + WAIT;
    while tally.answered.load(Ordering::Relaxed) < FLOODERS as u64
        && tokio::time::Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    (stop, tasks)
}

/// Ends the flood: its clients stop, and one stuck on an answer is dropped.
fn end_flood(stop: &AtomicBool, tasks: Vec<tokio::task::JoinHandle<()>>) {
    stop.store(true, Ordering::Relaxed);
    for t in tasks {
        t.abort();
    }
}

fn sim_args() -> Vec<String> {
    ["--sim", &JOINTS.to_string()]
        .iter()
        .map(|s| s.to_string())
        .collect()
}

#[test]
fn an_estop_is_answered_and_sent_during_a_flood() {
    let args = sim_args();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut d = Daemon::start_with(&args, |_| {});
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        wait_online(&client, &mut d, JOINTS, WAIT).await;
        let tally = Arc::new(Tally::default());
        let (stop, tasks) = flood(&d, &tally).await;
        let answer = tokio::time::timeout(
            ESTOP_WITHIN,
            reqwest::Client::new().post(d.url("/api/v1/estop")).send(),
        )
        .await;
        end_flood(&stop, tasks);
        let answer = answer
            .unwrap_or_else(|_| panic!("no e-stop answer within {ESTOP_WITHIN:?}"))
            .expect("e-stop request");
        let status = answer.status();
        let body: Value = answer.json().await.unwrap();
        assert_eq!(status, 200, "{body}");
        let bus = &body["buses"][0];
        // 0xFF to all first, then one per known device.
        assert!(
            bus["frames_sent"].as_u64().unwrap() > JOINTS as u64,
            "{body}"
        );
        // Each joint read back stopped, or (a read-back lost in the
        // flood) sent its disable without a confirmation; none driving.
        let count = |k: &str| bus[k].as_array().unwrap().len();
        assert_eq!(count("confirmed") + count("unconfirmed"), JOINTS, "{body}");
        assert_eq!(count("still_enabled"), 0, "{body}");
    });
}

#[test]
fn sigterm_during_a_flood_disables_the_joints_and_exits() {
    let args = sim_args();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut d = Daemon::start_with(&args, |_| {});
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let (stop, tasks) = rt.block_on(async {
        let client = reqwest::Client::new();
        wait_online(&client, &mut d, JOINTS, WAIT).await;
        let r = client
            .post(d.url("/api/v1/buses/sim0/control/enable"))
            .json(&json!({}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        flood(&d, &Arc::new(Tally::default())).await
    });
    d.signal(nix::sys::signal::Signal::SIGTERM);
    let status = d.wait_exit(WAIT);
    rt.block_on(async { end_flood(&stop, tasks) });
    let log = d.log();
    let status =
        status.unwrap_or_else(|| panic!("jointd still running {WAIT:?} after SIGTERM\n{log}"));
    assert!(status.success(), "exit status {status}\n{log}");
    assert!(
        log.contains("shutdown: disable sent to every joint"),
        "the joints were not disabled:\n{log}"
    );
    assert!(log.contains("stopped"), "{log}");
}
