//! `jointd doctor PATH`: the first thing to run when hardware arrives. It
//! checks a real bus against what jointd assumes of it and says, check by
//! check, what it found and what to do: what the port is and whether this
//! user may open it; the adapter's latency timer, output count (confirmed
//! writes) and echo; an idle line's noise; the baud the devices answer at;
//! each device's firmware, turnaround, CRC errors and timeouts; ids on two
//! devices; and the bus config jointd would run with, with its rates.
//!
//! It sends only reads ([`exchange`]): it never enables a motor, moves a
//! joint or writes RAM or flash. A port another process holds (a running
//! jointd's lock, a program with it open) is left untouched.
//!
//! # Layout
//! One-way: each file imports only from files above it.
//! - [`check`]: a check's verdict, what was found and what to do; timing spreads.
//! - [`port`]: what the port is, from sysfs and `/dev/serial`, before it is opened.
//! - [`access`]: who may open it and who holds it; what a failed open means.
//! - [`exchange`]: the only frames sent (INFO reads), and what comes back.
//! - [`adapter`]: latency timer, RS-485 direction, output count, echo.
//! - [`line`]: the idle line; the scan, baud by baud.
//! - [`devices`]: each device over a burst; ids on two devices.
//! - [`propose`]: the config jointd would run with, and its rates.
//! - [`report`]: the report, its verdict and exit status, `--json`.
//! - [`render`]: the report for a person.
//! - [`args`]: the command line.
//!
//! # Run order
//! 1. the port from the filesystem, and who holds it: another holder of a
//!    tty (not a pty, whose creator always has it) ends the run here;
//! 2. the open, exclusive as the daemon's (a held lock ends the run here,
//!    before termios is touched), raw at the first baud, RS-485 asked;
//! 3. the adapter as the open left it: latency timer, RS-485 direction;
//! 4. the idle line, listened to before anything is sent;
//! 5. the scan, at the first baud and then each other until someone answers;
//! 6. the output count, watched over reads of an id nobody answered;
//! 7. each device over a burst; duplicate ids; replies; states;
//! 8. the echo (over every write of the run), and the proposal.

pub mod access;
pub mod adapter;
pub mod args;
pub mod check;
pub mod devices;
pub mod exchange;
pub mod line;
pub mod port;
pub mod propose;
pub mod render;
pub mod report;

use std::io;
use std::path::{Path, PathBuf};

use crate::bus::config::Timing;
use crate::bus::loan::PortLoan;
use crate::protocol::MAX_DEVICE_ID;
use crate::transport::adapter::AdapterInfo;
use crate::transport::tty::{is_held, tty_opener};
use crate::transport::{Opener, Transport};

pub use args::{DoctorArgs, Options};
pub use check::{Check, CheckId, Verdict};
pub use report::{Report, EXIT_FAILED, EXIT_HELD, EXIT_OK};

use access::AccessFacts;
use adapter::AdapterFacts;
use exchange::Exchange;
use line::LineFacts;
use port::PortFacts;

/// Exit status: a baud no module speaks, a bad id list.
pub const EXIT_BAD_INPUT: u8 = 2;

/// `jointd doctor`: examines the port, prints the report, returns the
/// exit status ([`Report::exit_code`]).
pub fn run(args: &DoctorArgs) -> u8 {
    let options = match args.options() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("jointd doctor: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    // As the daemon opens a bus: exclusive, RS-485 direction asked.
    let opener = tty_opener(args.path.clone(), true);
    let report = examine(&args.path, opener, &options);
    if args.json {
        println!("{}", report.to_json());
    } else {
        print!("{}", render::text(&report));
    }
    report.exit_code()
}

/// Examines the port at `path`, opened with `open` (a simulator's pty
/// opener in tests), and reports.
pub fn examine(path: &Path, mut open: Opener, options: &Options) -> Report {
    let (mut report, facts, access) = port_report(path, options);
    let holders = access::holders_check(&facts, &access);
    if holders.verdict == Verdict::Fail {
        report.push(holders);
        report.held = true;
        return report;
    }
    let (mut transport, notes) = match open(options.baud) {
        Ok(opened) => opened,
        Err(e) => {
            let check = if is_held(&e) {
                access::held_by_lock(&facts, &access)
            } else {
                access::open_failed(&e, &facts, &access)
            };
            report.held = check.id == CheckId::Held;
            report.push(check);
            return report;
        }
    };
    report.push(holders);
    report.push(access::permission_ok(&access));
    report.push(Check::ok(
        CheckId::Open,
        format!("raw 8N1 at {} baud", options.baud),
    ));
    let (info, notes) = adapter::facts_of(&notes);
    report.push(adapter::rs485_check(&facts.kind, &notes));
    report.push(adapter::latency_check(
        info.model,
        facts.latency_timer_ms,
        facts.latency_timer_path.as_deref(),
        facts.latency_timer_writable,
    ));
    let ran = examine_line(transport.as_mut(), &info, notes, options, None, &mut report);
    if let Err(e) = ran {
        report.push(run_failed(&e));
    }
    report
}

/// Examines the port of a configured bus, lent by its owner between its
/// own frames with every joint disabled ([`crate::bus::loan`]): the checks
/// from the adapter on. The port is the daemon's by design: who holds it
/// and whether it opens are not asked. An e-stop on the bus (or the bus
/// stopping) stops the run.
pub fn examine_lent(port: &mut dyn Transport, loan: &PortLoan, options: &Options) -> Report {
    let (mut report, facts, _) = port_report(&loan.path, options);
    report.push(Check::ok(
        CheckId::Open,
        format!(
            "lent by bus {} at {} baud; its polling paused for the run",
            loan.bus, loan.baud
        ),
    ));
    report.push(adapter::rs485_check(&facts.kind, &loan.notes));
    report.push(adapter::latency_check(
        loan.adapter.model,
        facts.latency_timer_ms,
        facts.latency_timer_path.as_deref(),
        facts.latency_timer_writable,
    ));
    let ran = examine_line(
        port,
        &loan.adapter,
        loan.notes.clone(),
        options,
        Some(&*loan.stop_asked),
        &mut report,
    );
    if let Err(e) = ran {
        report.push(run_failed(&e));
    }
    report
}

/// Step 1 of the run order, shared by both runs: what the port is, who
/// may open it, and the report begun with their checks.
fn port_report(path: &Path, options: &Options) -> (Report, PortFacts, AccessFacts) {
    let facts = port::inspect(path, &options.roots);
    let access = facts
        .device
        .as_deref()
        .map_or_else(AccessFacts::default, |d| access::inspect(d, &options.roots));
    let mut report = Report::new(options.baud, facts.clone(), access.clone());
    report.push(port::kind_check(&facts));
    report.push(port::stable_path_check(&facts));
    (report, facts, access)
}

/// The run ended early: the port failed, or an e-stop stopped it.
fn run_failed(e: &io::Error) -> Check {
    if e.kind() == io::ErrorKind::Interrupted {
        return Check::fail(
            CheckId::Open,
            format!("stopped before its end: {e}"),
            "run the check again once the e-stop is dealt with (or the daemon is back)",
        );
    }
    Check::fail(
        CheckId::Open,
        format!("the port failed during the run: {e}"),
        "replug the adapter and run the doctor again; `dmesg | tail` says what the kernel saw",
    )
}

/// Steps 4 to 8 of the run order, on the open port.
fn examine_line(
    port: &mut dyn Transport,
    info: &AdapterInfo,
    notes: Vec<String>,
    options: &Options,
    stop: Option<&(dyn Fn() -> bool + Sync)>,
    report: &mut Report,
) -> io::Result<()> {
    // What a previous program or the open left in the buffer is not ours.
    port.discard_input()?;
    let timing = Timing {
        reply_margin_us: options.reply_margin.as_micros() as u64,
        ..Timing::default()
    };
    let mut ex = Exchange::new(port, info.model, &timing);
    if let Some(stop) = stop {
        ex.stop_when(stop);
    }
    let idle = line::listen_idle(&mut ex, options.listen)?;
    report.push(line::idle_check(&idle));
    let (scans, answering) = line::find_baud(&mut ex, options.baud, &options.ids)?;
    let line = LineFacts {
        idle,
        scans,
        answering_baud: answering,
    };
    report.push(line::baud_check(
        options.baud,
        options.baud_given,
        answering,
    ));
    report.push(line::devices_check(&line, &options.ids));
    let count = adapter::measure_count(&mut ex, absent_id(&line), options.writes)?;
    report.push(adapter::count_check(&count, info.usb));
    let devices = examine_devices(&mut ex, &line, options, report)?;
    report.push(adapter::echo_check(&ex.tally));
    if let Some(p) = proposal(&report.port, &line, &devices, info, &count) {
        report.push(propose::proposal_check(&p));
        report.proposal = Some(p);
    }
    report.adapter = Some(AdapterFacts {
        model: info.model.to_string(),
        found_by: info.found_by.clone(),
        usb: info.usb,
        notes,
        count,
        tally: ex.tally,
    });
    report.line = Some(line);
    report.devices = devices;
    Ok(())
}

/// Each device that answered (or garbled) at the answering baud, over a
/// burst; then the checks made of them all.
fn examine_devices(
    ex: &mut Exchange<'_>,
    line: &LineFacts,
    options: &Options,
    report: &mut Report,
) -> io::Result<Vec<devices::DeviceFacts>> {
    let Some(scan) = line.answering_scan() else {
        return Ok(Vec::new());
    };
    let mut ids: Vec<u8> = scan.answered.iter().chain(&scan.garbled).copied().collect();
    ids.sort_unstable();
    let mut found = Vec::new();
    for id in ids {
        found.push(devices::examine(ex, id, options.burst)?);
    }
    report.push(devices::duplicate_check(&found, scan));
    report.push(devices::replies_check(&found, scan));
    report.push(devices::state_check(&found));
    Ok(found)
}

/// The highest id nobody answered to, at any baud tried: the reads the
/// output count is watched over go to it.
fn absent_id(line: &LineFacts) -> u8 {
    let heard = |id: &u8| {
        line.scans
            .iter()
            .any(|s| s.answered.contains(id) || s.garbled.contains(id))
    };
    (1..=MAX_DEVICE_ID)
        .rev()
        .find(|id| !heard(id))
        .unwrap_or(MAX_DEVICE_ID)
}

/// The config jointd would run with, once devices answered.
fn proposal(
    facts: &PortFacts,
    line: &LineFacts,
    devices: &[devices::DeviceFacts],
    info: &AdapterInfo,
    count: &adapter::CountFacts,
) -> Option<propose::Proposal> {
    let scan = line.answering_scan().filter(|s| !s.answered.is_empty())?;
    let path: PathBuf = facts
        .by_id
        .first()
        .cloned()
        .unwrap_or_else(|| facts.path.clone());
    let turnaround = devices
        .iter()
        .filter_map(|d| d.turnaround)
        .max_by(|a, b| a.p50_us.total_cmp(&b.p50_us));
    Some(propose::propose(&propose::Inputs {
        path: &path,
        baud: scan.baud,
        ids: scan.answered.clone(),
        adapter: info.model,
        usb_confirm: adapter::believable(count),
        turnaround,
        revisions: devices.iter().filter_map(|d| d.revision.clone()).collect(),
    }))
}
