//! The `jointd` binary: `--sim` serves the API, a non-loopback bind needs a
//! token, SIGTERM stops it cleanly (joints disabled, exit 0).

use std::process::Command;
use std::time::{Duration, Instant};

mod support;
use support::daemon::{Daemon, BIN, WAIT};

#[test]
fn refuses_a_public_bind_without_a_token() {
    let out = Command::new(BIN)
        .args(["--sim", "1", "--listen", "0.0.0.0:0"])
        .env_remove("JOINTD_TOKEN")
        .output()
        .expect("run jointd");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("refusing to listen on 0.0.0.0:0 without a token"),
        "{err}"
    );
}

#[test]
fn an_empty_or_blank_token_stops_the_daemon_at_start() {
    for (token, why) in [("", "it is empty"), ("   ", "it is only whitespace")] {
        let out = Command::new(BIN)
            .args(["--sim", "1", "--listen", "127.0.0.1:0", "--token", token])
            .env_remove("JOINTD_TOKEN")
            .output()
            .expect("run jointd");
        assert!(!out.status.success(), "{token:?} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("token") && err.contains(why),
            "{token:?}: {err}"
        );
    }
    // The environment variable is held to the same rule.
    let out = Command::new(BIN)
        .args(["--sim", "1", "--listen", "127.0.0.1:0"])
        .env("JOINTD_TOKEN", "")
        .output()
        .expect("run jointd");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("JOINTD_TOKEN"));
}

#[test]
fn serves_the_simulator_and_stops_cleanly_on_sigterm() {
    let mut d = Daemon::spawn(&[
        "run",
        "--sim",
        "3",
        "--listen",
        "127.0.0.1:0",
        "--token",
        "t0k",
    ]);
    let base = d.base.clone();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        let get = |path: &str| {
            client
                .get(format!("{base}{path}"))
                .bearer_auth("t0k")
                .send()
        };
        let deadline = Instant::now() + WAIT;
        // Ready once the bus is up and every joint has answered.
        loop {
            let devices: serde_json::Value = get("/api/v1/buses/sim0/devices")
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            let online = devices["devices"]
                .as_array()
                .map_or(0, |d| d.iter().filter(|d| d["online"] == true).count());
            if online == 3 {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "joints never came online: {devices}"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        assert_eq!(get("/readyz").await.unwrap().status(), 200);
        let r = client
            .post(format!("{base}/api/v1/buses/sim0/devices/1/enable"))
            .bearer_auth("t0k")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(
            client
                .get(format!("{base}/healthz"))
                .send()
                .await
                .unwrap()
                .status(),
            200
        );
    });
    let status = d.stop();
    assert!(status.success(), "exit status {status}");
}

/// `--sim-adapter`: the simulated bus runs over the in-memory line (a pty
/// may pass a write on later than any USB adapter would), the bus plans
/// for the model, writes its polls blind, and the simulator's referee
/// counts no collision while every joint is polled.
#[test]
fn the_simulator_behind_an_adapter_model_is_pipelined_without_collisions() {
    let mut d = Daemon::spawn(&[
        "--sim",
        "4",
        "--sim-adapter",
        "ch340",
        "--listen",
        "127.0.0.1:0",
    ]);
    let base = d.base.clone();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let bus = rt.block_on(async {
        let get = |path: String| async move {
            reqwest::get(path)
                .await
                .unwrap()
                .json::<serde_json::Value>()
                .await
                .unwrap()
        };
        let deadline = Instant::now() + WAIT;
        loop {
            let bus = get(format!("{base}/api/v1/buses/sim0")).await;
            // All polls, not only those written blind: a host too busy to
            // write sentinels in time backs a CH340 off to lockstep, which
            // waits for each reply.
            if bus["counters"]["polls"].as_u64() >= Some(2000) {
                break bus;
            }
            assert!(Instant::now() < deadline, "too few polls: {bus}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    d.kill();
    assert!(
        bus["counters"]["polls_pipelined"].as_u64() > Some(0),
        "{bus}"
    );
    assert_eq!(bus["path"], "memory", "{bus}");
    assert_eq!(bus["adapter"], "ch340", "{bus}");
    // A collision corrupts the reply it meets (a CRC error, bytes skipped)
    // or loses it (a timeout).
    assert_eq!(bus["counters"]["crc_errors"], 0, "{bus}");
    assert_eq!(bus["counters"]["timeouts"], 0, "{bus}");
    assert_eq!(bus["counters"]["skipped_bytes"], 0, "{bus}");
}

/// A burst of identical failing requests (a bus that is down) logs O(1)
/// lines: the answers are 503, the log says so once, collapsed.
#[test]
fn a_burst_of_failing_requests_logs_one_line() {
    let mut cmd = Daemon::command(&[
        "run",
        "--bus",
        "x=/dev/jointd-test-nonexistent@500000",
        "--listen",
        "127.0.0.1:0",
    ]);
    cmd.env("RUST_LOG", "info");
    let mut d = Daemon::start(cmd);
    let base = d.base.clone();
    const BURST: usize = 50;
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        for _ in 0..BURST {
            let r = client
                .post(format!("{base}/api/v1/buses/x/estop"))
                .json(&serde_json::json!({}))
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 503);
        }
    });
    d.stop();
    let err = d.log_to_end();
    // "status=503", not "503": a timestamp's digits hold 503 now and then.
    let failures: Vec<&str> = err.lines().filter(|l| l.contains("status=503")).collect();
    assert_eq!(failures.len(), 1, "{err}");
    assert!(failures[0].contains("WARN"), "{err}");
    assert!(!err.contains("ERROR"), "{err}");
}
