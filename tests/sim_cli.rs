//! `jointd sim` as a user runs it: the device path is the first line of
//! stdout, the tty answers, stdin switches faults, Ctrl-C stops it cleanly.

mod support;

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Command as Process, Stdio};

use jointd::protocol::InfoBlock;
use jointd::transport::tty::TtyPort;
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use support::sim::*;

#[test]
fn sim_prints_its_path_answers_takes_faults_and_stops_on_sigint() {
    let mut child = Process::new(env!("CARGO_BIN_EXE_jointd"))
        .args([
            "sim",
            "--ids",
            "1-2",
            "--baud",
            "500000",
            "--align-ms",
            "50",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run jointd sim");
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    stdout.read_line(&mut first).unwrap();
    let path = PathBuf::from(first.trim());
    let (port, _) = TtyPort::open(&path, BAUD).expect("open the printed path");
    let mut host = Host {
        port: Box::new(port),
        decoder: Default::default(),
    };
    let ids: Vec<u8> = (0..2)
        .filter_map(|_| host.recv(WAIT).map(|r| r.dev_id))
        .collect();
    assert_eq!(ids, vec![1, 2], "both announced");
    assert!(host.read(2, InfoBlock::Info01).is_some());
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "drop 1.0 2").unwrap();
    stdin.flush().unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut answer = String::new();
    stderr.read_line(&mut answer).unwrap();
    assert!(answer.starts_with("ok:"), "{answer}");
    assert!(
        host.read(2, InfoBlock::Info01).is_none(),
        "replies of 2 dropped"
    );
    assert!(host.read(1, InfoBlock::Info01).is_some());
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let status = child.wait().unwrap();
    assert!(status.success(), "{status:?}");
    let mut stats = String::new();
    stderr.read_line(&mut stats).unwrap();
    let v: serde_json::Value = serde_json::from_str(&stats).expect("final stats as JSON");
    assert_eq!(v["dropped_replies"], 1);
    assert!(!path.exists(), "the link is removed on exit");
}

#[test]
fn sim_measure_reports_timing_and_occupancy_as_json() {
    let out = Process::new(env!("CARGO_BIN_EXE_jointd"))
        .args(["sim", "--ids", "1", "--measure", "50"])
        .output()
        .expect("run jointd sim --measure");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON report");
    // Losses depend on how loaded the machine is; they are reported, not asserted.
    assert!(v["lost"].as_u64().unwrap() < 50);
    assert_eq!(v["model_poll_us"], 900.0);
    assert!(v["delivery_error_us"]["p50"].is_number());
    assert!(v["saturated_occupancy"].as_f64().unwrap() >= 0.99);
    assert!(v["idle_occupancy"].as_f64().unwrap() < 0.01);
}
