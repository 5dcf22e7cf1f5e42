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
//! - `moves`: `--moves`: back-to-back moves generated in the daemon.
//! - `grasp`: `--grasp`: grasps on the simulator's objects and in free air.
//! - `grasp_modes`: `--grasp-modes` (and after `--grasp`): position mode
//!   against current mode on the joint physics.

pub mod analysis;
pub mod client;
pub mod cpu;
mod grasp;
mod grasp_modes;
mod moves;
pub mod pty_lag;
pub mod report;
mod send_floor;
pub mod ws;

use std::time::{Duration, Instant};

use clap::Args;
use thiserror::Error;

use crate::bus::{
    spawn_bus_on, spawn_bus_with, AdapterSetting, BusConfig, BusError, BusHandle, BusThread,
    Targets, THREAD_PREFIX,
};
use crate::protocol::status::fsm;
use crate::sim::{
    AdapterModel, Fault, SimConfig, SimError, SimHandle, SimStats, Simulator, WriteDelay,
};

use analysis::Analysis;
use client::{Client, CLIENT_THREAD};
use report::Report;

/// Arguments of `jointd bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Baud rate of a workload; repeat for several (default: 500000 and 230400).
    #[arg(long = "baud", default_values_t = [500_000u32, 230_400])]
    pub bauds: Vec<u32>,
    /// Joints on the bus (ids 1..=N).
    #[arg(long, default_value_t = 16)]
    pub joints: u8,
    /// How often the client writes every joint's target, Hz.
    #[arg(long, default_value_t = 1000)]
    pub rate_hz: u32,
    /// Measured time per workload, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Streaming time before measuring, seconds.
    #[arg(long, default_value_t = 2.0)]
    pub warmup: f64,
    /// Overrides the poll plan's control share of the wire (default: the bus default).
    #[arg(long)]
    pub control_share: Option<f64>,
    /// The simulated devices' turnaround, µs.
    #[arg(long, default_value_t = 100)]
    pub turnaround_us: u64,
    /// Overrides how long the owner looks at the port without sleeping once
    /// a reply is due, µs (default: the bus default; 0 = always sleep).
    #[arg(long)]
    pub reply_spin_us: Option<u64>,
    /// Run every thread at normal priority. By default the simulator (the
    /// referee) runs at real-time priority 30, the bus owner at its default
    /// 10 and the client at 10, so other work on the machine does not decide
    /// the result.
    #[arg(long)]
    pub no_rt: bool,
    /// Print the frames around every collision the simulator saw.
    #[arg(long)]
    pub show_collisions: bool,
    /// The USB adapter the simulated bus sits behind (`native`, `ftdi[:MS]`,
    /// `ch340`, `cp2102`, `ft232h[:MS]`); the bus is told the same. The
    /// report gives each rate as a share of what that adapter allows.
    #[arg(long, default_value = "native")]
    pub adapter: String,
    /// Behind an adapter: from the start of the measured window, host
    /// writes reach it late by a random delay with these quantiles, µs
    /// (`P50,P99,MAX` or `P50,P99,P99.9,MAX`, e.g. `38,150,750,1000`); the
    /// report adds the collisions of each second.
    #[arg(long, value_name = "P50,P99[,P99.9],MAX")]
    pub write_delay_us: Option<String>,
    /// Run this many buses at once, each with `--joints` joints on its own
    /// simulator and owner, after one bus carrying all of them: what a
    /// second adapter buys (per-joint rates, the ratio, the CPU).
    #[arg(long, default_value_t = 1)]
    pub buses: u8,
    /// How the bus reaches the simulator: `pty` (opened by path, like
    /// hardware) or `memory` (an in-process pipe that dates each write when
    /// it is made: under load a pty's kernel worker passes bytes on up to
    /// milliseconds late, a delay USB-serial drivers do not add, which the
    /// adapter models then take for a write that missed its USB frame).
    /// Default: `pty` on a native line, `memory` behind a USB adapter model.
    #[arg(long, value_parser = ["pty", "memory"])]
    pub line: Option<String>,
    /// Measure moves generated in the daemon instead: every joint
    /// doing back-to-back minimum-jerk moves of 300 ms; the rate of move
    /// setpoints on the wire per joint, the tracking error, occupancy, CPU.
    #[arg(long)]
    pub moves: bool,
    /// Measure grasping instead: three fingers closing on the simulator's
    /// objects at two stiffnesses, on V2.0.1 and rev 2.0.8 firmware (time
    /// to contact, force overshoot, hold error), then 100 grasps in free
    /// air counting false contacts; then the position/current mode
    /// comparison of `--grasp-modes`.
    #[arg(long)]
    pub grasp: bool,
    /// Only compare position mode with current mode for grasping, on the
    /// simulated joint physics directly (no bus, no daemon).
    #[arg(long)]
    pub grasp_modes: bool,
    /// Measure the WebSocket path instead: the engine alone, the
    /// same stream through /api/v1/ws, then with telemetry clients added.
    #[arg(long)]
    pub ws: bool,
    /// With --ws: telemetry clients subscribed to every joint.
    #[arg(long, default_value_t = 100)]
    pub telemetry_clients: usize,
    /// With --ws: each telemetry client's rate, Hz.
    #[arg(long, default_value_t = 100.0)]
    pub telemetry_hz: f64,
    /// Beside the run, measure how late a pty of its own passes bytes on
    /// (a frame's worth every millisecond, written at the owner's priority
    /// and read at the simulator's): on a pty line that lag reaches an
    /// adapter model as writes that came late.
    #[arg(long)]
    pub pty_lag: bool,
    /// Behind an adapter model on the in-memory line: do not confirm writes
    /// (the bus setting `timing.usb_confirm = false`), as on a port that
    /// cannot say when the adapter took a write: the blind pipeline and
    /// its guard ladder.
    #[arg(long)]
    pub no_confirm: bool,
}

/// Real-time priorities of the bench's threads (the owner's is its config default).
const SIM_PRIORITY: u8 = 30;
const CLIENT_PRIORITY: u8 = 10;

#[derive(Debug, Error)]
pub enum BenchError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("bus: {0}")]
    Bus(#[from] BusError),
    #[error("{0}")]
    Setup(String),
    #[error("i/o: {0}")]
    Io(#[from] std::io::Error),
}

/// Align time of the simulated joints: short, the bench is about the bus.
const ALIGN: Duration = Duration::from_millis(100);
/// Bound on each setup step (discovery, enable); the steps end on the event.
const SETUP_WAIT: Duration = Duration::from_secs(10);
/// Thread name prefix of the simulator's runner.
pub(crate) const SIM_THREAD: &str = "jointd-sim";

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
        let reports = reports.into_iter().collect::<Result<Vec<_>, _>>()?;
        let mean = |r: &Report, f: fn(&Analysis) -> &std::collections::BTreeMap<u8, f64>| {
            Analysis::mean_rate(f(&r.analysis))
        };
        let control = |r: &Report| mean(r, |a| &a.control_hz);
        let telemetry = |r: &Report| mean(r, |a| &a.telemetry_hz);
        for (i, r) in reports.iter().enumerate() {
            println!(
                "== bus {} of {n}, {} joints, at the same time\n{r}",
                i + 1,
                args.joints
            );
        }
        let worst =
            |f: &dyn Fn(&Report) -> f64| reports.iter().map(f).fold(f64::INFINITY, f64::min);
        let (c_gain, t_gain) = (
            worst(&control) / control(&single).max(f64::EPSILON),
            worst(&telemetry) / telemetry(&single).max(f64::EPSILON),
        );
        // The owners' threads share one name prefix: each report's owner
        // CPU is every owner's together.
        println!(
            "== {n} buses of {} vs one of {total} at {baud} baud: control per joint x{c_gain:.2}, \
             telemetry per joint x{t_gain:.2} (goal x{MIN_SPLIT_GAIN}); all bus owners {:.1} % of a core, \
             all simulators {:.1} %",
            args.joints,
            reports[0].cpu_owner * 100.0,
            reports[0].cpu_sim * 100.0,
        );
        let ok = c_gain >= MIN_SPLIT_GAIN
            && t_gain >= MIN_SPLIT_GAIN
            && reports.iter().all(|r| r.collisions == 0);
        println!(
            "  [{}] per-joint rates >= {MIN_SPLIT_GAIN}x one bus's, zero collisions",
            if ok { "ok" } else { "FAIL" }
        );
        all &= ok;
    }
    Ok(all)
}

fn adapter_of(args: &BenchArgs) -> Result<AdapterModel, BenchError> {
    AdapterModel::parse(&args.adapter).map_err(BenchError::Setup)
}

/// `--write-delay-us`, checked: it needs an adapter model.
fn write_delay_of(args: &BenchArgs) -> Result<Option<WriteDelay>, BenchError> {
    let Some(spec) = args.write_delay_us.as_deref() else {
        return Ok(None);
    };
    if !adapter_of(args)?.is_latent() {
        return Err(BenchError::Setup(
            "--write-delay-us needs a USB adapter model (--adapter ch340, ...)".into(),
        ));
    }
    WriteDelay::parse(spec).map(Some).map_err(BenchError::Setup)
}

/// What splitting the joints over two adapters must at least buy per joint.
const MIN_SPLIT_GAIN: f64 = 1.95;

pub(crate) fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}

fn workload(args: &BenchArgs, baud: u32) -> Result<Report, BenchError> {
    let ids: Vec<u8> = (1..=args.joints).collect();
    let (sim, bus, thread) = setup(args, baud, &ids)?;
    let probe = match args.pty_lag {
        true if args.no_rt => Some(pty_lag::PtyLagProbe::start((0, 0))?),
        true => Some(pty_lag::PtyLagProbe::start((
            CLIENT_PRIORITY,
            SIM_PRIORITY,
        ))?),
        false => None,
    };
    let run = measure(args, &sim, &bus, &ids)?;
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
        analysis: analysis::analyse(&run.log, &run.writes, &ids, s0.at, s1.at),
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

/// The simulator on a pty, the bus owner on its path (like hardware),
/// every joint online, enabled and aligned.
pub(crate) fn setup(
    args: &BenchArgs,
    baud: u32,
    ids: &[u8],
) -> Result<(SimHandle, BusHandle, BusThread), BenchError> {
    setup_with(args, baud, ids, |_| {})
}

/// [`setup`] with a last word on the simulator's config.
pub(crate) fn setup_with(
    args: &BenchArgs,
    baud: u32,
    ids: &[u8],
    tweak: impl FnOnce(&mut SimConfig),
) -> Result<(SimHandle, BusHandle, BusThread), BenchError> {
    let mut sim_cfg = SimConfig::new(ids.to_vec(), baud);
    tweak(&mut sim_cfg);
    sim_cfg.align_time = ALIGN;
    sim_cfg.turnaround = Duration::from_micros(args.turnaround_us);
    let adapter = adapter_of(args)?;
    sim_cfg.adapter = adapter;
    let (sim, memory) = match args.line.as_deref() {
        Some("memory") => {
            let (sim, host) = Simulator::spawn_memory(sim_cfg)?;
            (sim, Some(host))
        }
        Some(_) => (Simulator::spawn_pty(sim_cfg)?, None),
        None => Simulator::spawn_for(sim_cfg)?,
    };
    if !args.no_rt {
        referee_realtime()?;
    }
    let path = match &memory {
        Some(_) => std::path::PathBuf::from(crate::sim::MEMORY_LINE_PATH),
        None => sim
            .device_path()
            .ok_or_else(|| BenchError::Setup("the simulator has no pty path".into()))?,
    };
    let mut cfg = BusConfig::new("bench", path, baud);
    cfg.ids = ids.to_vec();
    cfg.adapter = AdapterSetting::Fixed(adapter);
    cfg.timing.turnaround_us = args.turnaround_us;
    if args.no_rt {
        cfg.timing.rt_priority = 0;
    }
    if args.no_confirm {
        cfg.timing.usb_confirm = false;
    }
    if let Some(spin) = args.reply_spin_us {
        cfg.timing.reply_spin_us = spin;
    }
    if let Some(share) = args.control_share {
        cfg.poll.control_share = share;
    }
    let (bus, thread) = match (memory, sim.pty_opener()) {
        (Some(host), _) => spawn_bus_on(cfg, Box::new(host))?,
        (None, Some(opener)) => spawn_bus_with(cfg, opener)?,
        (None, None) => return Err(BenchError::Setup("the simulator has no pty".into())),
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(bring_up(&bus, ids.len()))?;
    wait_running(&sim, ids)?;
    Ok((sim, bus, thread))
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

/// The simulator's runner thread at real-time priority: a referee the OS
/// holds back mis-times replies and collisions.
fn referee_realtime() -> Result<(), BenchError> {
    // A new thread names itself once it runs: look again for a moment.
    let deadline = Instant::now() + SETUP_WAIT;
    let mut tids = cpu::tids(SIM_THREAD);
    while tids.is_empty() {
        if Instant::now() > deadline {
            return Err(BenchError::Setup("no simulator thread found".into()));
        }
        std::thread::sleep(Duration::from_millis(1));
        tids = cpu::tids(SIM_THREAD);
    }
    for tid in tids {
        crate::rt::set_fifo(tid, SIM_PRIORITY).map_err(|e| {
            BenchError::Setup(format!(
                "real-time priority for the simulator refused ({e}); run with --no-rt"
            ))
        })?;
    }
    Ok(())
}

/// Waits for every joint online, then enables them all.
async fn bring_up(bus: &BusHandle, n: usize) -> Result<(), BenchError> {
    let mut rx = bus.watch();
    let online = rx.wait_for(|s| s.devices.values().filter(|d| d.online).count() >= n);
    match tokio::time::timeout(SETUP_WAIT, online).await {
        Ok(Ok(_)) => {}
        _ => return Err(BenchError::Setup(format!("not all {n} joints came online"))),
    }
    bus.enable(Targets::All).await?;
    Ok(())
}

/// Waits until the simulated joints finished aligning (bounded; the
/// simulator offers no event for it).
fn wait_running(sim: &SimHandle, ids: &[u8]) -> Result<(), BenchError> {
    let deadline = Instant::now() + SETUP_WAIT;
    while !ids
        .iter()
        .all(|id| sim.device(*id).is_some_and(|d| d.fsm == fsm::RUN))
    {
        if Instant::now() > deadline {
            return Err(BenchError::Setup("joints did not reach run".into()));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

const CPU_THREADS: [&str; 3] = [THREAD_PREFIX, SIM_THREAD, CLIENT_THREAD];

fn cpu_now() -> Vec<Duration> {
    cpu::snapshot(&CPU_THREADS)
}

fn cpu_share(a: &[Duration], b: &[Duration], s0: &SimStats, s1: &SimStats, i: usize) -> f64 {
    let wall = s1.at.saturating_duration_since(s0.at).as_secs_f64();
    let used = b[i].saturating_sub(a[i]).as_secs_f64();
    used / wall.max(f64::EPSILON)
}
