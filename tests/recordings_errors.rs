//! Recordings that cannot be made or written fail cleanly: a bus named
//! twice is refused (422), a file the disk will not take is a problem (507)
//! with no file left and no panic, a write that fails mid-way or a file
//! removed from the disk ends the recording saying which.
//!
//! The disk cannot be filled from a test, and the tests run as root (who
//! ignores permissions): the daemon is started with a file size limit
//! (RLIMIT_FSIZE, SIGXFSZ ignored) instead, under which the kernel fails
//! the recording's writes with EFBIG, through the very writes a full disk
//! fails with ENOSPC.

#[path = "support/daemon.rs"]
mod daemon;

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use daemon::{wait_online, Daemon};
use serde_json::{json, Value};

const WAIT: Duration = Duration::from_secs(30);

fn state_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("jointd-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The files in `dir` (none when it does not exist).
fn files_in(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir).map_or_else(
        |_| Vec::new(),
        |d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        },
    )
}

/// Files the daemon writes may hold `bytes` at most.
fn file_size_limit(bytes: u64) -> impl FnOnce(&mut Command) {
    move |cmd: &mut Command| {
        // SAFETY: between fork and exec only async-signal-safe calls
        // (setrlimit, signal), touching no memory of the parent's.
        unsafe {
            cmd.pre_exec(move || {
                let limit = libc::rlimit {
                    rlim_cur: bytes,
                    rlim_max: bytes,
                };
                if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // A write past the limit then fails with EFBIG instead of
                // killing the process.
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                Ok(())
            });
        }
    }
}

async fn post(client: &reqwest::Client, d: &Daemon, body: Value) -> (u16, Value) {
    let r = client
        .post(d.url("/api/v1/recordings"))
        .json(&body)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

async fn get(client: &reqwest::Client, d: &Daemon, path: &str) -> (u16, Value) {
    let r = client.get(d.url(path)).send().await.unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

/// Waits until recording `id` is no longer `recording`; its view.
async fn wait_ended(client: &reqwest::Client, d: &Daemon, id: u64) -> Value {
    let deadline = Instant::now() + WAIT;
    loop {
        let (_, v) = get(client, d, &format!("/api/v1/recordings/{id}")).await;
        if v["state"] != "recording" {
            return v;
        }
        assert!(Instant::now() < deadline, "recording never ended: {v}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[test]
fn a_bus_named_twice_is_refused_and_nothing_starts() {
    let dir = state_dir("rec-dup");
    let d = Daemon::start_with(
        &["--sim", "2", "--state-dir", dir.to_str().unwrap()],
        |_| {},
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        let names: Vec<&str> = std::iter::repeat("sim0").take(1000).collect();
        let (status, p) = post(&client, &d, json!({"buses": names})).await;
        assert_eq!(status, 422, "{p}");
        assert_eq!(p["field"], "buses[1]", "{p}");
        let detail = p["detail"].as_str().unwrap();
        assert!(detail.contains("`sim0` appears twice"), "{detail}");
        let (_, list) = get(&client, &d, "/api/v1/recordings").await;
        assert_eq!(list["recordings"], json!([]), "{list}");
    });
    assert!(files_in(&dir.join("recordings")).is_empty());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_file_the_disk_will_not_take_is_507_and_leaves_no_file() {
    let dir = state_dir("rec-full");
    let mut d = Daemon::start_with(
        &["--sim", "2", "--state-dir", dir.to_str().unwrap()],
        file_size_limit(0),
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        let (status, p) = post(&client, &d, json!({})).await;
        assert_eq!(status, 507, "{p}");
        assert_eq!(p["type"], "urn:jointd:problem:storage-full", "{p}");
        let detail = p["detail"].as_str().unwrap();
        assert!(detail.contains("File too large"), "{detail}");
        // Nothing half-made: no file, no recording, and a place is free.
        let (_, list) = get(&client, &d, "/api/v1/recordings").await;
        assert_eq!(list["recordings"], json!([]), "{list}");
        assert!(files_in(&dir.join("recordings")).is_empty());
        for _ in 0..5 {
            let (status, _) = post(&client, &d, json!({})).await;
            assert_eq!(status, 507, "a failed start must not keep its place");
        }
        let (status, _) = get(&client, &d, "/healthz").await;
        assert_eq!(status, 200);
    });
    assert!(!d.log().contains("panicked"), "{}", d.log());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_recordings_directory_that_cannot_be_made_is_503_not_a_panic() {
    let dir = state_dir("rec-nodir");
    // A file where the directory should be.
    std::fs::write(dir.join("recordings"), b"in the way").unwrap();
    let mut d = Daemon::start_with(
        &["--sim", "1", "--state-dir", dir.to_str().unwrap()],
        |_| {},
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        let (status, p) = post(&client, &d, json!({})).await;
        assert_eq!(status, 503, "{p}");
        assert_eq!(p["type"], "urn:jointd:problem:recording-unwritable", "{p}");
        assert!(p["detail"].as_str().unwrap().contains("recordings"), "{p}");
    });
    assert!(!d.log().contains("panicked"), "{}", d.log());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_write_that_fails_mid_recording_ends_it_failed_saying_why() {
    let dir = state_dir("rec-midway");
    // Room for the header and a chunk or two of 16 joints' traffic.
    let mut d = Daemon::start_with(
        &["--sim", "16", "--state-dir", dir.to_str().unwrap()],
        file_size_limit(48 * 1024),
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        wait_online(&client, &mut d, 16, WAIT).await;
        let (status, v) = post(&client, &d, json!({})).await;
        assert_eq!(status, 201, "{v}");
        let id = v["id"].as_u64().unwrap();
        let v = wait_ended(&client, &d, id).await;
        assert_eq!(v["state"], "failed", "{v}");
        let error = v["error"].as_str().unwrap();
        assert!(
            error.contains("writing the file failed") && error.contains("File too large"),
            "{error}"
        );
        // Its place is free again: another recording starts.
        let (status, v) = post(&client, &d, json!({"duration_s": 0.1})).await;
        assert_ne!(status, 409, "{v}");
    });
    assert!(!d.log().contains("panicked"), "{}", d.log());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_file_removed_while_recording_ends_it_saying_so() {
    let dir = state_dir("rec-removed");
    let mut d = Daemon::start_with(
        &["--sim", "2", "--state-dir", dir.to_str().unwrap()],
        |_| {},
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        wait_online(&client, &mut d, 2, WAIT).await;
        let (status, v) = post(&client, &d, json!({})).await;
        assert_eq!(status, 201, "{v}");
        let id = v["id"].as_u64().unwrap();
        let file = dir.join("recordings").join(v["file"].as_str().unwrap());
        std::fs::remove_file(&file).unwrap();
        let v = wait_ended(&client, &d, id).await;
        assert_eq!(v["state"], "failed", "{v}");
        let error = v["error"].as_str().unwrap();
        assert!(error.contains("removed from the disk"), "{error}");
        let (status, p) = get(&client, &d, &format!("/api/v1/recordings/{id}/file")).await;
        assert_eq!(status, 404, "{p}");
        assert_eq!(
            p["type"], "urn:jointd:problem:recording-file-removed",
            "{p}"
        );
    });
    let _ = std::fs::remove_dir_all(dir);
}
