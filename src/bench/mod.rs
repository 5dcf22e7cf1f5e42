//! `jointd bench`: the bus engine against the simulator over a pty, with a
//! client streaming every joint's target, measured by the simulator as
//! referee: 16 joints, every target written at 1 kHz.
//!
//! The simulator runs in this process (its frame log and the client share
//! one clock), so daemon CPU is the bus owner thread's own run time from
//! `/proc/self/task/*/schedstat`; the simulator's and the client's threads
//! are reported beside it, not charged to the daemon.
//!
//! # Layout
//! - [`client`]: the streaming client (angles encode which write they are).
//! - [`analysis`]: per-joint rates and setpoint-to-wire latency from the frame log.
//! - [`cpu`]: per-thread CPU time by thread name.
//! - [`report`]: the result, the engine's targets, the printout.
//! - `report_rows`: the printout's rows (results, the adapter's bound, where the wire time went).
//! - `moves`: `--moves`: back-to-back moves generated in the daemon.
//! - `grasp`: `--grasp`: grasps on the simulator's objects and in free air.
//! - `doctor`: `--doctor`: the doctor's proposed config run, its rates held to its prediction.
//! - `grasp_modes`: `--grasp-modes` (and after `--grasp`): position mode
//!   against current mode on the joint physics.

pub mod analysis;
mod args;
pub mod client;
pub mod cpu;
mod doctor;
mod grasp;
mod grasp_modes;
mod moves;
pub mod pty_lag;
pub mod report;
mod report_rows;
mod rig;
mod send_floor;
pub mod ws;

use std::time::{Duration, Instant};

use analysis::Analysis;
use client::Client;
use report::Report;
use rig::{
    adapter_of, cpu_now, cpu_share, load_average, setup, write_delay_of, CLIENT_PRIORITY,
    SIM_PRIORITY,
};

use crate::bus::BusHandle;
use crate::sim::{Fault, SimHandle, SimStats};
pub use args::{BenchArgs, BenchError};

/// Runs every workload and prints its report; true when all met their targets.
pub fn run(args: &BenchArgs) -> Result<bool, BenchError> {
    if !(args.seconds > 0.0 && args.warmup >= 0.0 && args.rate_hz > 0 && args.joints > 0) {
        return Err(BenchError::Setup(
            "seconds, rate and joints must be positive".into(),
        ));
    }
    println!(
        "jointd bench: load average {}; threads at {}",
        load_average(),
        if args.no_rt {
            "normal priority (other work on the machine skews the numbers)".to_string()
        } else {
            format!("real-time priority: simulator {SIM_PRIORITY}, bus owner and client {CLIENT_PRIORITY}")
        }
    );
    if args.grasp_modes {
        print!("{}", grasp_modes::report());
        return Ok(true);
    }
    if args.ws {
        return ws::run(args);
    }
    if args.doctor {
        return doctor::run(args);
    }
    if args.moves {
        return moves::run(args);
    }
    if args.grasp {
        return grasp::run(args);
    }
    if args.buses > 1 {
        return several_buses(args);
    }
    let mut all = true;
    for &baud in &args.bauds {
        let report = workload(args, baud)?;
        println!("{report}");
        all &= report.passed();
    }
    Ok(all)
}

/// Per-joint rates of one bus carrying every joint, then of `--buses`
/// buses of `--joints` each running at once; true when the buses' rates
/// are at least [`MIN_SPLIT_GAIN`] times the single bus's.
fn several_buses(args: &BenchArgs) -> Result<bool, BenchError> {
    let n = usize::from(args.buses);
    let total = u16::from(args.joints) * u16::from(args.buses);
    let total = u8::try_from(total)
        .ok()
        .filter(|t| *t <= 16)
        .ok_or_else(|| {
            BenchError::Setup("buses x joints must be at most 16 (one broadcast pair)".into())
        })?;
    let mut all = true;
    for &baud in &args.bauds {
        let one = BenchArgs {
            joints: total,
            buses: 1,
            ..args.clone()
        };
        let single = workload(&one, baud)?;
        println!("== one bus of {total} joints\n{single}");
        let reports = at_once(args, n, baud)?;
        for (i, r) in reports.iter().enumerate() {
            println!(
                "== bus {} of {n}, {} joints, at the same time\n{r}",
                i + 1,
                args.joints
            );
        }
        all &= split_gain(args, baud, &single, &reports);
    }
    Ok(all)
}

/// `n` buses of `args.joints` joints each, run at the same time.
fn at_once(args: &BenchArgs, n: usize, baud: u32) -> Result<Vec<Report>, BenchError> {
    let reports: Vec<Result<Report, BenchError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..n)
            .map(|_| scope.spawn(|| workload(args, baud)))
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(BenchError::Setup("a bus's bench thread panicked".into()))
                })
            })
            .collect()
    });
    reports.into_iter().collect()
}

/// Prints what the buses run at once (`reports`) bought per joint against
/// one bus of all their joints (`single`); true when each rate gained the
/// goal and no bus collided.
fn split_gain(args: &BenchArgs, baud: u32, single: &Report, reports: &[Report]) -> bool {
    let n = reports.len();
    let total = u16::from(args.joints) * n as u16;
    let mean = |r: &Report, f: fn(&Analysis) -> &std::collections::BTreeMap<u8, f64>| {
        Analysis::mean_rate(f(&r.analysis))
    };
    let control = |r: &Report| mean(r, |a| &a.control_hz);
    let telemetry = |r: &Report| mean(r, |a| &a.telemetry_hz);
    let worst = |f: &dyn Fn(&Report) -> f64| reports.iter().map(f).fold(f64::INFINITY, f64::min);
    let (c_gain, t_gain) = (
        worst(&control) / control(single).max(f64::EPSILON),
        worst(&telemetry) / telemetry(single).max(f64::EPSILON),
    );
    let (cpu_owner, cpu_sim) = reports
        .first()
        .map_or((0.0, 0.0), |r| (r.cpu_owner, r.cpu_sim));
    // The owners' threads share one name prefix: each report's owner
    // CPU is every owner's together.
    println!(
        "== {n} buses of {} vs one of {total} at {baud} baud: control per joint x{c_gain:.2}, \
         telemetry per joint x{t_gain:.2} (goal x{MIN_SPLIT_GAIN}); all bus owners {:.1} % of a core, \
         all simulators {:.1} %",
        args.joints,
        cpu_owner * 100.0,
        cpu_sim * 100.0,
    );
    let ok = c_gain >= MIN_SPLIT_GAIN
        && t_gain >= MIN_SPLIT_GAIN
        && reports.iter().all(|r| r.collisions == 0);
    println!(
        "  [{}] per-joint rates >= {MIN_SPLIT_GAIN}x one bus's, zero collisions",
        if ok { "ok" } else { "FAIL" }
    );
    ok
}

/// What splitting the joints over two adapters must at least buy per joint.
const MIN_SPLIT_GAIN: f64 = 1.95;

fn workload(args: &BenchArgs, baud: u32) -> Result<Report, BenchError> {
    let ids: Vec<u8> = (1..=args.joints).collect();
    let (sim, bus, thread) = setup(args, baud, &ids)?;
    measured(args, baud, &ids, sim, bus, thread)
}

/// The pty's own read lag, probed beside the run when asked, at the
/// client's and simulator's priorities (none with `--no-rt`).
fn pty_lag_probe(args: &BenchArgs) -> Result<Option<pty_lag::PtyLagProbe>, BenchError> {
    if !args.pty_lag {
        return Ok(None);
    }
    let priorities = match args.no_rt {
        true => (0, 0),
        false => (CLIENT_PRIORITY, SIM_PRIORITY),
    };
    Ok(Some(pty_lag::PtyLagProbe::start(priorities)?))
}

/// The load run on a rig already up (every joint running), measured; the
/// rig stopped after.
fn measured(
    args: &BenchArgs,
    baud: u32,
    ids: &[u8],
    sim: SimHandle,
    bus: BusHandle,
    thread: crate::bus::BusThread,
) -> Result<Report, BenchError> {
    let probe = pty_lag_probe(args)?;
    let run = measure(args, &sim, &bus, ids)?;
    let pty_lag = probe.map(pty_lag::PtyLagProbe::finish).transpose()?;
    if args.show_collisions {
        crate::sim::collision_context(&run.log)
            .iter()
            .for_each(|l| println!("{l}"));
    }
    let mut referee_late_ns = sim.delivery_errors_ns();
    referee_late_ns.sort_unstable();
    let snapshot = bus.snapshot();
    for note in &snapshot.port_notes {
        println!("  note from the bus owner: {note}");
    }
    thread.stop();
    sim.shutdown();
    let (s0, s1) = (&run.stats[0], &run.stats[1]);
    let share = |i: usize| cpu_share(&run.cpu[0], &run.cpu[1], s0, s1, i);
    Ok(Report {
        baud,
        adapter: adapter_of(args)?,
        turnaround: Duration::from_micros(args.turnaround_us),
        joints: ids.len(),
        rate_hz: args.rate_hz,
        warmup: Duration::from_secs_f64(args.warmup),
        occupancy: SimStats::occupancy(s0, s1),
        collisions: s1.collisions.saturating_sub(s0.collisions),
        write_delay: write_delay_of(args)?,
        collisions_by_second: run.collisions_by_second,
        modes_by_second: run.modes_by_second,
        slipped_writes: s1
            .host_writes_slipped
            .saturating_sub(s0.host_writes_slipped),
        pipeline: snapshot.usb_pipeline.clone(),
        analysis: analysis::analyse(&run.log, &run.writes, ids, s0.at, s1.at),
        cpu_owner: share(0),
        cpu_sim: share(1),
        cpu_client: share(2),
        daemon: snapshot.rates.clone(),
        referee_undated: s1.host_reads_undated.saturating_sub(s0.host_reads_undated),
        pty_lag,
        referee_late_us: [0.5, 0.99]
            .map(|p| analysis::quantile_i64(&referee_late_ns, p) as f64 / 1e3),
        counters: snapshot.counters.clone(),
    })
}

/// What one measured window left behind.
struct Run {
    /// Simulator counters and thread CPU times at the window's start and end.
    stats: [SimStats; 2],
    cpu: [Vec<Duration>; 2],
    writes: Vec<client::Write>,
    log: Vec<crate::sim::WireFrame>,
    /// Behind a USB adapter: the referee's collisions in each second of
    /// the window, and the pipeline's mode at the end of each.
    collisions_by_second: Vec<u64>,
    modes_by_second: Vec<&'static str>,
}

/// Streams targets through the warm-up and the measured window.
fn measure(
    args: &BenchArgs,
    sim: &SimHandle,
    bus: &BusHandle,
    ids: &[u8],
) -> Result<Run, BenchError> {
    let period = Duration::from_secs_f64(1.0 / f64::from(args.rate_hz));
    let client_rt = if args.no_rt { 0 } else { CLIENT_PRIORITY };
    let client = Client::start(bus.clone(), ids.to_vec(), period, client_rt)?;
    std::thread::sleep(Duration::from_secs_f64(args.warmup));
    sim.clear_frame_log();
    let (s0, cpu0) = (sim.stats(), cpu_now());
    let mut collisions_by_second = Vec::new();
    let mut modes_by_second = Vec::new();
    let delay = write_delay_of(args)?;
    if let Some(delay) = delay {
        sim.inject(Fault::WriteDelay(Some(delay)));
    }
    if adapter_of(args)?.is_latent() {
        (collisions_by_second, modes_by_second) =
            collisions_each_second(sim, bus, &s0, args.seconds);
    } else {
        std::thread::sleep(Duration::from_secs_f64(args.seconds));
    }
    let (s1, cpu1) = (sim.stats(), cpu_now());
    sim.inject(Fault::WriteDelay(None));
    let writes = client.finish();
    Ok(Run {
        stats: [s0, s1],
        cpu: [cpu0, cpu1],
        writes,
        log: sim.frame_log(),
        collisions_by_second,
        modes_by_second,
    })
}

/// Sleeps through the window, noting the referee's collisions each second
/// (a last part second included) and the bus's pipeline mode at its end.
fn collisions_each_second(
    sim: &SimHandle,
    bus: &BusHandle,
    start: &SimStats,
    seconds: f64,
) -> (Vec<u64>, Vec<&'static str>) {
    let end = start.at + Duration::from_secs_f64(seconds);
    let mut last = start.collisions;
    let (mut collisions, mut modes) = (Vec::new(), Vec::new());
    let mut next = start.at;
    while next < end {
        next = (next + Duration::from_secs(1)).min(end);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        let now = sim.stats().collisions;
        collisions.push(now.saturating_sub(last));
        last = now;
        let mode = bus
            .snapshot()
            .usb_pipeline
            .as_ref()
            .map(|p| p.mode.as_str());
        modes.push(mode.unwrap_or("none"));
    }
    (collisions, modes)
}
