//! `--doctor`: the doctor's proposal held to what it predicts. The doctor
//! examines a fresh simulated bus (as `jointd doctor` would the user's),
//! the bus owner then runs the config it proposed under the bench's load
//! (every joint's target streamed), and the rates measured by the referee
//! are set against the ones it predicted: within [`TOLERANCE`] each.
//!
//! The predicted control rate is capped at the client's own rate: a joint
//! cannot be updated more often than it is sent a target.

use std::time::{Duration, Instant};

use super::analysis::Analysis;
use super::args::{BenchArgs, BenchError};
use super::rig::{spawn_sim, start_bus, SimLine, SETUP_WAIT};
use crate::bus::loan::PortLoan;
use crate::doctor::{self, Options};
use crate::transport::adapter::AdapterInfo;

/// How far a measured rate may fall from the prediction, either way.
pub(crate) const TOLERANCE: f64 = 0.05;

/// Each `--baud`: the doctor, then the load on its config; true when
/// every rate is within [`TOLERANCE`] of its prediction with no collision.
pub(super) fn run(args: &BenchArgs) -> Result<bool, BenchError> {
    let mut all = true;
    for &baud in &args.bauds {
        all &= one_baud(args, baud)?;
    }
    Ok(all)
}

fn one_baud(args: &BenchArgs, baud: u32) -> Result<bool, BenchError> {
    let ids: Vec<u8> = (1..=args.joints).collect();
    let mut line = spawn_sim(args, baud, &ids, |_| {})?;
    announced(&line, ids.len())?;
    let report = examine(args, &mut line, baud)?;
    let proposal = report.proposal.clone().ok_or_else(|| {
        BenchError::Setup(format!(
            "the doctor proposed no config:\n{}",
            doctor::render::text(&report)
        ))
    })?;
    println!(
        "== the doctor's proposal at {baud} baud (verdict {:?})\n{}",
        report.verdict, proposal.toml
    );
    let mut cfg = proposal.config.clone();
    cfg.path = line.path.clone();
    let (sim, bus, thread) = start_bus(args, line, cfg, &ids)?;
    let measured = super::measured(args, baud, &ids, sim, bus, thread)?;
    println!("{measured}");
    let predicted = &proposal.rates;
    let control_goal = predicted.control_hz.min(f64::from(args.rate_hz));
    let control = Analysis::mean_rate(&measured.analysis.control_hz);
    let telemetry = Analysis::mean_rate(&measured.analysis.telemetry_hz);
    let rows = [
        ("control per joint", control, control_goal),
        ("telemetry per joint", telemetry, predicted.telemetry_hz),
    ];
    let mut ok = measured.collisions == 0;
    println!(
        "== measured against the doctor's prediction ({})",
        predicted.bound
    );
    for (what, got, want) in rows {
        let ratio = got / want.max(f64::EPSILON);
        let within = (ratio - 1.0).abs() <= TOLERANCE;
        ok &= within;
        println!(
            "  [{}] {what}: {got:.1} Hz measured, {want:.1} Hz predicted: {ratio:.3} (within ±{:.0} %)",
            if within { "ok" } else { "FAIL" },
            TOLERANCE * 100.0
        );
    }
    println!("  collisions: {}", measured.collisions);
    Ok(ok)
}

/// Waits until every device announced its power-up: the doctor listens
/// to an idle line first.
fn announced(line: &SimLine, n: usize) -> Result<(), BenchError> {
    let deadline = Instant::now() + SETUP_WAIT;
    while line.sim.stats().announcements < n as u64 {
        if Instant::now() > deadline {
            return Err(BenchError::Setup("the devices never announced".into()));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

/// The doctor on the line: by its path on a pty (with the simulated
/// adapter's output count, as `jointd doctor` opens it), on the pipe's
/// host end otherwise (lent as a running bus lends its port).
fn examine(args: &BenchArgs, line: &mut SimLine, baud: u32) -> Result<doctor::Report, BenchError> {
    let options = Options {
        ids: (1..=16).collect(),
        ..Options::new(Some(baud))
    };
    let adapter = super::rig::adapter_of(args)?;
    match line.host.as_mut() {
        None => {
            let opener = line
                .sim
                .pty_opener(true)
                .ok_or_else(|| BenchError::Setup("the simulator has no pty".into()))?;
            Ok(doctor::examine(&line.path, opener, &options))
        }
        Some(host) => {
            let loan = PortLoan {
                bus: "bench".into(),
                path: line.path.clone(),
                baud,
                adapter: AdapterInfo {
                    model: adapter,
                    found_by: "the simulator's adapter model".into(),
                    tty_without_usb: false,
                    usb: adapter.is_latent(),
                },
                notes: Vec::new(),
                ids: Vec::new(),
                reply_margin: options.reply_margin,
                stop_asked: Box::new(|| false),
            };
            Ok(doctor::examine_lent(host, &loan, &options))
        }
    }
}
