//! `jointd doctor` against the simulator on a pty: each fault it must tell
//! apart (an adapter that echoes, devices at another baud, two devices
//! with one id, an output count that never falls) named with its fix; a
//! clean bus ok, with a config the daemon reads; a port a running daemon
//! holds left untouched, with a non-zero exit status.
//!
//! The doctor runs in this process (as `jointd bench` does) so that it
//! opens the pty with the simulated adapter's output count; the held port
//! is the binary's own run. Assertions are on counts and verdicts, never
//! on timings.

mod support;

use std::process::Command;
use std::time::Duration;

use jointd::doctor::{examine, render, CheckId, Options, Report, Verdict, EXIT_HELD, EXIT_OK};
use jointd::sim::{AdapterModel, Fault, SimConfig, SimHandle, Simulator};
use support::daemon::{Daemon, BIN};
use support::sim::{config, wait_for, BAUD};

/// A seed whose first draw keeps device 2's scan reply
/// ([`a_device_losing_replies_is_named_with_its_timeouts_and_the_fix`]).
const DROP_SEED: u64 = 2;

/// A reply is waited for this long past its modelled time: the
/// simulator is a thread behind a pty on a loaded machine, where the
/// daemon's 5 ms default does not always cover its lateness.
const REPLY_MARGIN: Duration = Duration::from_millis(50);

/// A short run: ids 1–8 scanned, short bursts, a short idle listen.
fn options(baud: u32) -> Options {
    Options {
        ids: (1..=8).collect(),
        burst: 12,
        writes: 40,
        listen: Duration::from_millis(100),
        reply_margin: REPLY_MARGIN,
        ..Options::new(Some(baud))
    }
}

/// The simulator on a pty, its power-up announcements over, and the
/// doctor's report on it.
fn doctor(cfg: SimConfig, options: &Options) -> (SimHandle, Report) {
    let devices = cfg.ids.len() as u64;
    let sim = Simulator::spawn_pty(cfg).expect("spawn the simulator");
    wait_for("the power-up announcements", || {
        (sim.stats().announcements >= devices).then_some(())
    });
    let path = sim.device_path().expect("a pty path");
    let opener = sim.pty_opener(true).expect("a pty opener");
    let report = examine(&path, opener, options);
    (sim, report)
}

fn fix_of(report: &Report, id: CheckId) -> String {
    let check = report.check(id).expect("the check was made");
    check.fix.clone().unwrap_or_default()
}

#[test]
fn a_clean_bus_is_ok_and_gets_a_config_the_daemon_reads() {
    let (_sim, r) = doctor(config(&[1, 2, 3, 4]), &options(BAUD));
    let text = render::text(&r);
    for id in [
        CheckId::Held,
        CheckId::Baud,
        CheckId::Devices,
        CheckId::Echo,
        CheckId::DuplicateIds,
    ] {
        assert_eq!(r.verdict_of(id), Some(Verdict::Ok), "{id:?}\n{text}");
    }
    assert_eq!(r.count(Verdict::Fail), 0, "{text}");
    assert_eq!(r.exit_code(), EXIT_OK);
    let ids: Vec<u8> = r.devices.iter().map(|d| d.id).collect();
    assert_eq!(ids, vec![1, 2, 3, 4]);
    assert!(r
        .devices
        .iter()
        .all(|d| d.revision.as_deref() == Some("2.0.1")));
    assert!(r
        .devices
        .iter()
        .all(|d| d.firmware.as_deref() == Some("1.2.8")));
    let p = r.proposal.as_ref().expect("a proposal");
    assert_eq!(
        (p.config.ids.clone(), p.config.baud),
        (vec![1, 2, 3, 4], BAUD)
    );
    assert!(
        p.rates.control_hz > 0.0 && p.rates.telemetry_hz > 0.0,
        "{:?}",
        p.rates
    );
    let file: jointd::daemon::FileConfig =
        toml::from_str(&p.toml).expect("the daemon reads the proposal");
    assert_eq!(file.buses, vec![p.config.clone()]);
    assert!(text.contains("proposed bus config"), "{text}");
}

#[test]
fn an_adapter_that_echoes_is_named_with_its_fix() {
    let mut cfg = config(&[1, 2]);
    cfg.echo = true;
    let (sim, r) = doctor(cfg, &options(BAUD));
    let echo = r.check(CheckId::Echo).expect("the echo was checked");
    assert_eq!(echo.verdict, Verdict::Warn, "{}", render::text(&r));
    assert!(echo.found.contains("echoes"), "{}", echo.found);
    assert!(fix_of(&r, CheckId::Echo).contains("turn the echo off"));
    let tally = r.adapter.as_ref().expect("the adapter's facts").tally;
    assert!(tally.echoes * 2 >= tally.writes, "{tally:?}");
    assert!(sim.stats().echoes >= tally.echoes);
    // Its own frames are not replies: the devices are found as ever.
    assert_eq!(r.verdict_of(CheckId::Baud), Some(Verdict::Ok));
    assert_eq!(r.devices.len(), 2);
}

#[test]
fn devices_at_another_baud_are_found_there_with_the_fix() {
    // The devices run at 500000; the doctor is told 230400.
    let (sim, r) = doctor(config(&[1, 2]), &options(230_400));
    let baud = r.check(CheckId::Baud).expect("the baud was checked");
    assert_eq!(baud.verdict, Verdict::Fail, "{}", render::text(&r));
    assert!(baud.found.contains("500000"), "{}", baud.found);
    assert!(fix_of(&r, CheckId::Baud).contains("@500000"));
    let line = r.line.as_ref().expect("the line's facts");
    assert_eq!(line.answering_baud, Some(500_000));
    assert_eq!(line.scans[0].baud, 230_400);
    assert!(!line.scans[0].heard_anyone());
    assert_eq!(line.answering_scan().expect("a scan").answered, vec![1, 2]);
    assert_eq!(
        r.proposal.as_ref().expect("a proposal").config.baud,
        500_000
    );
    assert!(
        sim.stats().baud_mismatches > 0,
        "the 230400 reads reached the devices as garbage"
    );
}

#[test]
fn two_devices_with_one_id_are_named_with_the_fix() {
    let (_sim, r) = doctor(config(&[1, 2, 2, 3]), &options(BAUD));
    let dup = r
        .check(CheckId::DuplicateIds)
        .expect("duplicates were checked");
    assert_eq!(dup.verdict, Verdict::Fail, "{}", render::text(&r));
    assert!(dup.found.contains("ids 2 "), "{}", dup.found);
    assert!(fix_of(&r, CheckId::DuplicateIds).contains("one at a time"));
    let scan = r
        .line
        .as_ref()
        .and_then(|l| l.answering_scan())
        .expect("a scan");
    assert_eq!(
        (scan.answered.clone(), scan.garbled.clone()),
        (vec![1, 3], vec![2])
    );
    // The others are judged apart from it, and the config leaves it out.
    assert_ne!(r.verdict_of(CheckId::Replies), Some(Verdict::Fail));
    assert_eq!(
        r.proposal.as_ref().expect("a proposal").config.ids,
        vec![1, 3]
    );
}

#[test]
fn an_output_count_that_never_falls_is_named_with_usb_confirm_off() {
    let mut cfg = config(&[1]);
    cfg.adapter = AdapterModel::Ch340;
    cfg.stuck_count = true;
    let (_sim, r) = doctor(cfg, &options(BAUD));
    let count = r
        .check(CheckId::OutputCount)
        .expect("the count was checked");
    assert_eq!(count.verdict, Verdict::Fail, "{}", render::text(&r));
    assert!(fix_of(&r, CheckId::OutputCount).contains("usb_confirm = false"));
    let facts = &r.adapter.as_ref().expect("the adapter's facts").count;
    assert!(
        facts.readable && facts.fell == 0 && facts.never_fell == facts.writes,
        "{facts:?}"
    );
    let proposal = r.proposal.as_ref().expect("a proposal");
    assert!(!proposal.config.timing.usb_confirm);
    assert!(
        proposal.toml.contains("usb_confirm = false"),
        "{}",
        proposal.toml
    );
}

#[test]
fn an_output_count_that_falls_keeps_confirmed_writes() {
    let mut cfg = config(&[1]);
    cfg.adapter = AdapterModel::Ch340;
    let (_sim, r) = doctor(cfg, &options(BAUD));
    assert_ne!(
        r.verdict_of(CheckId::OutputCount),
        Some(Verdict::Fail),
        "{}",
        render::text(&r)
    );
    let facts = &r.adapter.as_ref().expect("the adapter's facts").count;
    assert!(facts.readable && facts.fell > 0, "{facts:?}");
    assert!(
        r.proposal
            .as_ref()
            .expect("a proposal")
            .config
            .timing
            .usb_confirm
    );
}

#[test]
fn a_port_a_running_daemon_holds_is_left_alone_with_a_non_zero_exit() {
    let sim = Simulator::spawn_pty(config(&[1, 2])).expect("spawn the simulator");
    let path = sim.device_path().expect("a pty path");
    let path = path.to_str().expect("a UTF-8 path").to_string();
    let mut daemon = Daemon::start_with(&["--bus", &format!("{path}@{BAUD}")], |_| {});
    daemon.log_line(&["bus up"]);
    let before = sim.stats();
    // At another baud than the daemon's: had the doctor set up the port,
    // the daemon's frames would reach the devices as garbage.
    let out = Command::new(BIN)
        .args(["doctor", &path, "--baud", "230400", "--json"])
        .output()
        .expect("run jointd doctor");
    assert_eq!(
        out.status.code(),
        Some(i32::from(EXIT_HELD)),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("a JSON report");
    assert_eq!(report["held"], true);
    let checks = report["checks"].as_array().expect("checks");
    let held = checks
        .iter()
        .find(|c| c["id"] == "held")
        .expect("the held check");
    assert_eq!(held["verdict"], "fail");
    assert!(
        held["found"]
            .as_str()
            .unwrap_or_default()
            .contains("jointd"),
        "{held}"
    );
    assert!(
        report["line"].is_null() && report["adapter"].is_null(),
        "nothing examined"
    );
    assert_eq!(sim.stats().baud_mismatches, before.baud_mismatches);
    assert!(!daemon.log().contains("bus down"), "{}", daemon.log());
}

/// The doctor after its power-up announcements, with `fault` injected
/// before it starts.
fn doctor_with(cfg: SimConfig, fault: Fault, options: &Options) -> (SimHandle, Report) {
    let devices = cfg.ids.len() as u64;
    let sim = Simulator::spawn_pty(cfg).expect("spawn the simulator");
    wait_for("the power-up announcements", || {
        (sim.stats().announcements >= devices).then_some(())
    });
    sim.inject(fault);
    let path = sim.device_path().expect("a pty path");
    let opener = sim.pty_opener(true).expect("a pty opener");
    let report = examine(&path, opener, options);
    (sim, report)
}

#[test]
fn noise_on_an_idle_line_is_named_with_the_fix() {
    let every = Duration::from_millis(10);
    let (sim, r) = doctor_with(config(&[1, 2]), Fault::Noise(Some(every)), &options(BAUD));
    let idle = r.check(CheckId::IdleLine).expect("the idle line was heard");
    assert_eq!(idle.verdict, Verdict::Warn, "{}", render::text(&r));
    assert!(idle.found.contains("noise"), "{}", idle.found);
    assert!(fix_of(&r, CheckId::IdleLine).contains("terminate the line"));
    assert!(sim.stats().noise_bursts > 0);
}

/// Device 2 loses some of its replies: the seed makes which ones fixed
/// (the simulator draws for a reply only where a drop rate is set), so
/// its scan is answered and its burst is not whole, whatever the timing.
#[test]
fn a_device_losing_replies_is_named_with_its_timeouts_and_the_fix() {
    let mut cfg = config(&[1, 2, 3]);
    cfg.seed = DROP_SEED;
    let drop = Fault::DropReplies {
        dev_id: Some(2),
        rate: 0.3,
    };
    let (sim, r) = doctor_with(cfg, drop, &options(BAUD));
    let text = render::text(&r);
    let ids: Vec<u8> = r.devices.iter().map(|d| d.id).collect();
    assert_eq!(ids, vec![1, 2, 3], "{text}");
    let replies = r.check(CheckId::Replies).expect("the replies were judged");
    assert_ne!(replies.verdict, Verdict::Ok, "{text}");
    assert!(replies.found.contains("id 2: "), "{}", replies.found);
    assert!(!replies.found.contains("id 1: ") && !replies.found.contains("id 3: "));
    assert!(fix_of(&r, CheckId::Replies).contains("timeouts"));
    let two = &r.devices[1];
    assert_eq!(
        u64::from(two.timeouts),
        sim.stats().dropped_replies,
        "{two:?}"
    );
    assert!(two.timeouts > 0);
}
