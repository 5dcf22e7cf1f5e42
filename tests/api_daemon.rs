//! The `jointd` binary: `--sim` serves the API, a non-loopback bind needs a
//! token, SIGTERM stops it cleanly (joints disabled, exit 0).

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_jointd");
const WAIT: Duration = Duration::from_secs(20);

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

/// Starts `jointd` with `args`; returns it and its base URL (the first
/// line it prints).
fn spawn_daemon(args: &[&str]) -> (std::process::Child, String) {
    let mut child = Command::new(BIN)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn jointd");
    let mut first = String::new();
    let stdout = child.stdout.take().expect("stdout");
    BufReader::new(stdout)
        .read_line(&mut first)
        .expect("first line");
    let base = first
        .trim()
        .strip_prefix("listening on ")
        .expect("address line")
        .to_owned();
    (child, base)
}

#[test]
fn serves_the_simulator_and_stops_cleanly_on_sigterm() {
    let (mut child, base) = spawn_daemon(&[
        "run",
        "--sim",
        "3",
        "--listen",
        "127.0.0.1:0",
        "--token",
        "t0k",
    ]);
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
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let deadline = Instant::now() + WAIT;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "jointd did not exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "exit status {status}");
}

/// `--sim-adapter`: the simulated bus runs over the in-memory line (a pty
/// may pass a write on later than any USB adapter would), the bus plans
/// for the model, writes its polls blind, and the simulator's referee
/// counts no collision while every joint is polled.
#[test]
fn the_simulator_behind_an_adapter_model_is_pipelined_without_collisions() {
    let (mut child, base) = spawn_daemon(&[
        "--sim",
        "4",
        "--sim-adapter",
        "ch340",
        "--listen",
        "127.0.0.1:0",
    ]);
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
            if bus["counters"]["polls_pipelined"].as_u64() >= Some(2000) {
                break bus;
            }
            assert!(Instant::now() < deadline, "too few polls: {bus}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    let _ = child.kill();
    let _ = child.wait();
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
    let mut child = Command::new(BIN)
        .args([
            "run",
            "--bus",
            "x=/dev/jointd-test-nonexistent@500000",
            "--listen",
            "127.0.0.1:0",
        ])
        .env("RUST_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn jointd");
    let mut first = String::new();
    let stdout = child.stdout.take().expect("stdout");
    BufReader::new(stdout)
        .read_line(&mut first)
        .expect("first line");
    let base = first
        .trim()
        .strip_prefix("listening on ")
        .expect("address line")
        .to_owned();
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
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let out = child.wait_with_output().expect("jointd exits");
    let err = String::from_utf8_lossy(&out.stderr);
    // "status=503", not "503": a timestamp's digits hold 503 now and then.
    let failures: Vec<&str> = err.lines().filter(|l| l.contains("status=503")).collect();
    assert_eq!(failures.len(), 1, "{err}");
    assert!(failures[0].contains("WARN"), "{err}");
    assert!(!err.contains("ERROR"), "{err}");
}
