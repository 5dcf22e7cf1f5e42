//! A bad state file never keeps the daemon from serving, and what it holds
//! is checked as any request is: the real binary on the simulator with a
//! `state_dir`, given a truncated, empty or mistyped `state.json` (set aside
//! beside it, e-stop served), a file with bad calibrations among good ones
//! (those dropped, the rest kept), and the REST routes that save poses and
//! calibrations given what the file must never hold.

mod support;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use support::http::Server;
use support::tmp::TestDir;

const BIN: &str = env!("CARGO_BIN_EXE_jointd");
const WAIT: Duration = Duration::from_secs(20);
const IDS: u8 = 3;

/// A daemon on `--sim 3` whose log (stderr) is collected as it comes.
struct Daemon {
    child: Child,
    server: Server,
    log: Arc<Mutex<String>>,
}

impl Daemon {
    fn start(config: &Path) -> Self {
        let mut child = Command::new(BIN)
            .args(["--sim", &IDS.to_string(), "--listen", "127.0.0.1:0"])
            .arg("--config")
            .arg(config)
            .env("RUST_LOG", "info")
            // The simulator's pty link goes in the test's dir, removed with it.
            .env("TMPDIR", config.parent().expect("the config's dir"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn jointd");
        let log = Arc::new(Mutex::new(String::new()));
        let sink = Arc::clone(&log);
        let stderr = child.stderr.take().expect("stderr");
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let mut all = sink.lock().unwrap();
                all.push_str(&line);
                all.push('\n');
            }
        });
        let mut first = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut first)
            .expect("first line");
        let base = first
            .trim()
            .strip_prefix("listening on ")
            .map(str::to_owned);
        let base = base.unwrap_or_else(|| {
            let _ = child.wait();
            panic!(
                "the daemon did not start (first line {first:?}); its log:\n{}",
                log.lock().unwrap()
            )
        });
        let server = Server {
            base,
            client: reqwest::Client::new(),
            token: None,
        };
        Self { child, server, log }
    }

    /// The first log line holding `what`, waited for.
    fn log_line(&self, what: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let log = self.log.lock().unwrap().clone();
            if let Some(line) = log.lines().find(|l| l.contains(what)) {
                return line.to_owned();
            }
            assert!(
                Instant::now() < deadline,
                "no log line with {what:?}:\n{log}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    async fn online(&self) {
        let deadline = Instant::now() + WAIT;
        loop {
            let bus = self.server.get("/api/v1/buses/sim0").await;
            if bus.body["devices_online"] == u64::from(IDS) {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "joints never online: {}",
                bus.body
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fresh directory with a config of one hand on the simulated bus and its
/// state directory; returns (the directory, config path, state directory).
fn setup(name: &str) -> (TestDir, PathBuf, PathBuf) {
    let dir = TestDir::new(&format!("safety-{name}"));
    let state = dir.join("state");
    std::fs::create_dir_all(&state).unwrap();
    let config = dir.join("jointd.toml");
    std::fs::write(
        &config,
        format!(
            r#"state_dir = "{}"

[[hand]]
name = "left"
joints = [{{ bus = "sim0", ids = "1-3", names = ["thumb", "index", "middle"] }}]
"#,
            state.display()
        ),
    )
    .unwrap();
    (dir, config, state)
}

/// The files of `dir` whose names start with `prefix`.
fn files_starting(dir: &Path, prefix: &str) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(prefix))
        })
        .collect();
    found.sort();
    found
}

const GOOD_STATE: &str = r#"{
  "version": 1,
  "poses": { "left": { "fist": { "thumb": 40.0, "index": 35.5 } } },
  "calibration": { "sim0": { "1": { "offset_deg": 12.0, "flip": true, "range_deg": [-5.0, 80.0] } } }
}"#;

/// `content` as state.json: the daemon starts, serves e-stop, the file sits
/// beside as state.json.bad-* with its content, the ERROR names both paths,
/// the hands view says so, and the next save writes a whole new file.
fn a_bad_state_file_is_set_aside(name: &str, content: &str) {
    let (_dir, config, state) = setup(name);
    let path = state.join("state.json");
    std::fs::write(&path, content).unwrap();
    let d = Daemon::start(&config);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        d.online().await;
        let stop = d.server.post_empty("/api/v1/estop").await;
        assert_eq!(stop.status.as_u16(), 200, "e-stop: {}", stop.body);

        let aside = files_starting(&state, "state.json.bad-");
        assert_eq!(aside.len(), 1, "one file set aside: {aside:?}");
        assert_eq!(std::fs::read_to_string(&aside[0]).unwrap(), content);
        assert!(
            !path.exists(),
            "the bad file is no longer where the daemon reads"
        );

        let line = d.log_line("set aside");
        assert!(line.contains("ERROR"), "{line}");
        assert!(line.contains(&path.display().to_string()), "{line}");
        assert!(line.contains(&aside[0].display().to_string()), "{line}");

        let hands = d.server.get("/api/v1/hands").await;
        let file = &hands.ok()["state_file"];
        assert_eq!(file["path"], path.display().to_string(), "{file}");
        assert_eq!(
            file["set_aside"]["moved_to"],
            aside[0].display().to_string(),
            "{file}"
        );
        assert!(file["set_aside"]["reason"].is_string(), "{file}");
        assert_eq!(hands.body["hands"][0]["poses"], json!([]));

        let pose = json!({"positions_deg": {"thumb": 10.0}});
        d.server
            .put("/api/v1/hands/left/poses/open", pose)
            .await
            .ok();
        let saved: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap())
            .expect("the new state file is whole JSON");
        assert_eq!(saved["poses"]["left"]["open"]["thumb"], 10.0);
    });
}

#[test]
fn a_truncated_state_file_is_set_aside_and_the_daemon_serves() {
    a_bad_state_file_is_set_aside("truncated", &GOOD_STATE[..GOOD_STATE.len() / 2]);
}

#[test]
fn an_empty_state_file_is_set_aside_and_the_daemon_serves() {
    a_bad_state_file_is_set_aside("empty", "");
}

#[test]
fn a_mistyped_state_file_is_set_aside_and_the_daemon_serves() {
    a_bad_state_file_is_set_aside(
        "mistyped",
        r#"{"version": 1, "poses": {"left": {"fist": {"thumb": "forty"}}}}"#,
    );
}

#[test]
fn bad_calibrations_in_the_file_are_dropped_and_the_rest_kept() {
    let (_dir, config, state) = setup("calibrations");
    let content = r#"{
  "version": 1,
  "poses": { "left": { "fist": { "thumb": 40.0, "index": 35.5 } } },
  "calibration": { "sim0": {
    "1": { "offset_deg": 12.0, "flip": true, "range_deg": [-5.0, 80.0] },
    "2": { "offset_deg": 1e308 },
    "3": { "offset_deg": 5.0, "range_deg": [60.0, -30.0] }
  } }
}"#;
    std::fs::write(state.join("state.json"), content).unwrap();
    let d = Daemon::start(&config);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        d.online().await;
        let kept = d
            .server
            .get("/api/v1/buses/sim0/devices/1/calibration")
            .await;
        assert_eq!(kept.ok()["offset_deg"], 12.0);
        assert_eq!(kept.body["flip"], true);
        assert_eq!(kept.body["range_deg"], json!([-5.0, 80.0]));
        for id in [2, 3] {
            let dropped = d
                .server
                .get(&format!("/api/v1/buses/sim0/devices/{id}/calibration"))
                .await;
            assert_eq!(
                dropped.ok()["offset_deg"],
                0.0,
                "joint {id}: {}",
                dropped.body
            );
            assert_eq!(dropped.body["range_deg"], Value::Null, "joint {id}");
        }
        let fist = d.server.get("/api/v1/hands/left/poses/fist").await;
        assert_eq!(
            fist.ok()["positions_deg"],
            json!({"thumb": 40.0, "index": 35.5})
        );

        for (id, why) in [(2, "offset_deg"), (3, "range_deg")] {
            let line = d.log_line(&format!("id={id} "));
            assert!(line.contains("WARN"), "{line}");
            assert!(line.contains("sim0") && line.contains(why), "{line}");
        }
        let hands = d.server.get("/api/v1/hands").await;
        let dropped = &hands.ok()["state_file"]["dropped_calibrations"];
        assert_eq!(dropped.as_array().map(Vec::len), Some(2), "{dropped}");
        assert_eq!(hands.body["state_file"]["set_aside"], Value::Null);
        assert!(files_starting(&state, "state.json.bad-").is_empty());
    });
}

/// A daemon on a fresh state directory, online; the runtime to call it.
fn online(name: &str) -> (Daemon, PathBuf, tokio::runtime::Runtime) {
    let (_dir, config, state) = setup(name);
    let d = Daemon::start(&config);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(d.online());
    (d, state, rt)
}

/// What reached the state file (nothing yet: empty).
fn saved(state: &Path) -> String {
    std::fs::read_to_string(state.join("state.json")).unwrap_or_default()
}

const JSON: [(&str, &str); 1] = [("Content-Type", "application/json")];

#[test]
fn rest_refuses_a_calibration_that_could_not_be_applied() {
    let (d, state, rt) = online("rest-cal");
    rt.block_on(async {
        let cal = "/api/v1/buses/sim0/devices/1/calibration";
        let inverted = d.server.put(cal, json!({"range_deg": [60.0, -30.0]})).await;
        let detail = inverted.problem(422)["detail"].as_str().unwrap().to_owned();
        assert!(detail.contains("range_deg"), "{detail}");
        let far = d.server.put(cal, json!({"offset_deg": 1e308})).await;
        let detail = far.problem(422)["detail"].as_str().unwrap().to_owned();
        assert!(detail.contains("offset_deg"), "{detail}");
        // JSON has no infinity: a number beyond f64 is refused by the parser
        // (400, naming the field) before any handler sees it.
        let body = r#"{"range_deg": [1e999, 10.0]}"#;
        let huge = d
            .server
            .browser(reqwest::Method::PUT, cal, &JSON, Some(body))
            .await;
        let detail = huge.problem(400)["detail"].as_str().unwrap().to_owned();
        assert!(detail.contains("range_deg"), "{detail}");
    });
    assert!(!saved(&state).contains("sim0"), "{}", saved(&state));
}

#[test]
fn rest_refuses_a_calibration_for_a_device_not_on_the_bus() {
    let (d, state, rt) = online("rest-absent");
    rt.block_on(async {
        let absent = "/api/v1/buses/sim0/devices/9/calibration";
        let unknown = d.server.put(absent, json!({"offset_deg": 5.0})).await;
        let problem = unknown.problem(404);
        assert_eq!(problem["type"], "urn:jointd:problem:unknown-device");
    });
    assert!(!saved(&state).contains("sim0"), "{}", saved(&state));
}

#[test]
fn rest_refuses_a_pose_with_a_joint_given_twice() {
    let (d, state, rt) = online("rest-dup");
    rt.block_on(async {
        let dup = r#"{"positions_deg": {"thumb": 10.0, "index": 5.0, "thumb": 20.0}}"#;
        let path = "/api/v1/hands/left/poses/fist";
        let pose = d
            .server
            .browser(reqwest::Method::PUT, path, &JSON, Some(dup))
            .await;
        let detail = pose.problem(422)["detail"].as_str().unwrap().to_owned();
        assert!(detail.contains("`thumb`"), "{detail}");
    });
    assert!(!saved(&state).contains("fist"), "{}", saved(&state));
}
