//! What a newcomer meets on the command line: the assumed baud
//! said aloud, a taken port that names `--listen`, a refused config value
//! with its line, a bus that is down answering "bus down" for every device
//! call (and nothing to disable at shutdown if it never opened), and a
//! shutdown that names the joints it disabled.

use std::process::Command;
use std::time::{Duration, Instant};

mod support;
use support::daemon::{Daemon, BIN, WAIT};

fn missing_device_path() -> String {
    format!("/tmp/jointd-test-no-such-tty-{}", std::process::id())
}

#[test]
fn a_bus_without_baud_logs_the_baud_it_assumes() {
    let path = missing_device_path();
    let mut d = Daemon::spawn(&["--bus", &path, "--listen", "127.0.0.1:0"]);
    let line = d.log_line(&["no @BAUD", "230400"]);
    assert!(line.contains(&format!("{path}@500000")), "{line}");
}

#[test]
fn a_taken_port_names_the_address_and_listen() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = taken.local_addr().expect("addr").to_string();
    let out = Command::new(BIN)
        .args(["--sim", "1", "--listen", &addr])
        .env_remove("JOINTD_TOKEN")
        .output()
        .expect("run jointd");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&addr) && err.contains("--listen"), "{err}");
    // It stopped before opening any bus: nothing to disable, nothing said
    // of one.
    for never in ["bus up", "disable", "WARN"] {
        assert!(
            !err.contains(never),
            "`{never}` from a daemon that never started: {err}"
        );
    }
}

#[test]
fn a_refused_config_value_is_reported_with_its_line_and_key() {
    let dir = std::env::temp_dir().join(format!("jointd-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("bad.toml");
    let text = "listen = \"127.0.0.1:0\"\n\n[[bus]]\nname = \"ok\"\npath = \"/dev/null\"\nbaud = 500000\n\n[[bus]]\nname = \"left\"\npath = \"/dev/null\"\n  baud = 123456\n";
    std::fs::write(&file, text).expect("write");
    let out = Command::new(BIN)
        .args(["--config", file.to_str().expect("utf-8 path")])
        .env_remove("JOINTD_TOKEN")
        .output()
        .expect("run jointd");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 11, column 3"), "{err}");
    assert!(
        err.contains("`baud`") && err.contains("left") && err.contains("123456"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn every_device_call_on_a_bus_that_is_down_answers_bus_down() {
    let path = missing_device_path();
    let spec = format!("gone={path}@500000");
    let d = Daemon::spawn(&["--bus", &spec, "--listen", "127.0.0.1:0"]);
    let base = format!("{}/api/v1/buses/gone", d.base);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    rt.block_on(async {
        let client = reqwest::Client::new();
        let deadline = Instant::now() + WAIT;
        loop {
            let bus: serde_json::Value = client
                .get(&base)
                .send()
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            if bus["link"] == "down" {
                break;
            }
            assert!(Instant::now() < deadline, "the bus never went down: {bus}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let json = |v: serde_json::Value| v;
        let calls = [
            (reqwest::Method::POST, "/devices/1/enable", None),
            (reqwest::Method::POST, "/devices/1/disable", None),
            (reqwest::Method::GET, "/devices/1", None),
            (reqwest::Method::GET, "/devices/1/config", None),
            (
                reqwest::Method::PUT,
                "/devices/1/target",
                Some(json(serde_json::json!({"position_deg": 1.0}))),
            ),
            (
                reqwest::Method::POST,
                "/control/enable",
                Some(json(serde_json::json!({"ids": [1]}))),
            ),
            (
                reqwest::Method::POST,
                "/scan",
                Some(json(serde_json::json!({"first": 1, "last": 2}))),
            ),
        ];
        for (method, path, body) in calls {
            let mut req = client.request(method.clone(), format!("{base}{path}"));
            if let Some(body) = body {
                req = req.json(&body);
            }
            let resp = req.send().await.unwrap();
            let status = resp.status().as_u16();
            let problem: serde_json::Value = resp.json().await.unwrap();
            assert_eq!(
                (status, problem["type"].as_str()),
                (503, Some("urn:jointd:problem:bus-down")),
                "{method} {path}: {problem}"
            );
        }
    });
}

#[test]
fn a_bus_that_never_opened_has_nothing_to_disable_at_shutdown() {
    let path = missing_device_path();
    let spec = format!("gone={path}@500000");
    let mut d = Daemon::spawn(&["--bus", &spec, "--listen", "127.0.0.1:0"]);
    // The API answering says the daemon is up to its signal handling.
    let base = format!("{}/api/v1/buses/gone", d.base);
    tokio::runtime::Runtime::new()
        .expect("runtime")
        .block_on(async {
            let deadline = Instant::now() + WAIT;
            loop {
                let bus: serde_json::Value =
                    reqwest::get(&base).await.unwrap().json().await.unwrap();
                if bus["link"] == "down" {
                    break;
                }
                assert!(Instant::now() < deadline, "the bus never went down: {bus}");
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        });
    assert!(d.stop().success());
    let log = d.log_to_end();
    let (_, after) = log
        .split_once("shutting down")
        .unwrap_or_else(|| panic!("no shutdown in:\n{log}"));
    // No disable tried on a port that never opened, so no warning that it
    // could not be sent.
    for never in ["disable", "WARN"] {
        assert!(!after.contains(never), "`{never}` at shutdown:\n{log}");
    }
}

#[test]
fn shutdown_logs_the_joints_it_disabled() {
    let mut d = Daemon::spawn(&["--sim", "3", "--listen", "127.0.0.1:0"]);
    let base = d.base.clone();
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    rt.block_on(async {
        let client = reqwest::Client::new();
        let deadline = Instant::now() + WAIT;
        let device = |client: reqwest::Client| {
            let url = format!("{base}/api/v1/buses/sim0/devices/2");
            async move {
                let dev: serde_json::Value =
                    client.get(url).send().await.unwrap().json().await.unwrap();
                dev
            }
        };
        // Enabled only once the bus has read device 2's state (INFO_01): the
        // first state read decides whether a joint was found enabled at start
        // (on_start), and that read must not be of the enable sent here.
        loop {
            let dev = device(client.clone()).await;
            if dev["status"]["state"] == "ready" {
                break;
            }
            assert!(Instant::now() < deadline, "device 2 never read: {dev}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        loop {
            let r = client
                .post(format!("{base}/api/v1/buses/sim0/devices/2/enable"))
                .send()
                .await
                .unwrap();
            if r.status() == 200 {
                break;
            }
            assert!(Instant::now() < deadline, "device 2 never enabled");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        // The shutdown line names the joints by their last reported state:
        // wait until a status poll has shown device 2 driving its motor.
        loop {
            let dev = device(client.clone()).await;
            if matches!(dev["status"]["state"].as_str(), Some("align" | "run")) {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "device 2 never reported enabled: {dev}"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    d.stop();
    let rest = d.log_to_end();
    let line = rest
        .lines()
        .find(|l| l.contains("shutdown: disable sent"))
        .unwrap_or_else(|| panic!("no shutdown line in:\n{rest}"));
    assert!(
        line.contains("[1, 2, 3]") && line.contains("enabled_before=[2]"),
        "{line}"
    );
}

#[test]
fn a_refused_soft_limit_is_reported_with_its_table_line() {
    let dir = std::env::temp_dir().join(format!("jointd-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("bad.toml");
    let text = "listen = \"127.0.0.1:0\"\n\n[[limit]]\nmin_deg = -90.0\n\n[[limit]]\nbus = \"sim0\"\nmax_deg = 500.0\n";
    std::fs::write(&file, text).expect("write");
    let out = Command::new(BIN)
        .args(["--config", file.to_str().expect("utf-8 path"), "--sim", "1"])
        .env_remove("JOINTD_TOKEN")
        .output()
        .expect("run jointd");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("line 6: [[limit]] #2") && err.contains("500"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
