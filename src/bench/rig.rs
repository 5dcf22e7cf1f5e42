//! The bench's rig: the simulator and the bus owner set up as a user's
//! would be (every joint online, enabled, aligned), the referee at
//! real-time priority, and the CPU the threads used.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::args::{BenchArgs, BenchError, SIM_THREAD};
use super::client::CLIENT_THREAD;
use super::cpu;
use crate::bus::{
    spawn_bus_on, spawn_bus_with, AdapterSetting, BusConfig, BusHandle, BusThread, Targets,
    THREAD_PREFIX,
};
use crate::protocol::status::fsm;
use crate::sim::{AdapterModel, SimConfig, SimHandle, SimStats, Simulator, WriteDelay};
use crate::transport::memory::MemoryPort;

/// Real-time priorities of the bench's threads (the owner's is its config default).
pub(crate) const SIM_PRIORITY: u8 = 30;

pub(crate) const CLIENT_PRIORITY: u8 = 10;

/// Align time of the simulated joints: short, the bench is about the bus.
pub(crate) const ALIGN: Duration = Duration::from_millis(100);

/// Bound on each setup step (discovery, enable); the steps end on the event.
pub(crate) const SETUP_WAIT: Duration = Duration::from_secs(10);

pub(crate) fn adapter_of(args: &BenchArgs) -> Result<AdapterModel, BenchError> {
    AdapterModel::parse(&args.adapter).map_err(BenchError::Setup)
}

/// `--write-delay-us`, checked: it needs an adapter model.
pub(crate) fn write_delay_of(args: &BenchArgs) -> Result<Option<WriteDelay>, BenchError> {
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

pub(crate) fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
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
    let line = spawn_sim(args, baud, ids, tweak)?;
    let cfg = bench_config(args, baud, ids, &line)?;
    start_bus(args, line, cfg, ids)
}

/// The simulated bus and how the owner reaches it.
pub(crate) struct SimLine {
    pub sim: SimHandle,
    /// The in-memory pipe's host end; `None` on a pty.
    pub host: Option<MemoryPort>,
    /// The pty's path, or the memory line's name.
    pub path: PathBuf,
}

/// The simulator for `args` (its adapter model, turnaround, line), the
/// referee at real-time priority unless `--no-rt`.
pub(crate) fn spawn_sim(
    args: &BenchArgs,
    baud: u32,
    ids: &[u8],
    tweak: impl FnOnce(&mut SimConfig),
) -> Result<SimLine, BenchError> {
    let mut sim_cfg = SimConfig::new(ids.to_vec(), baud);
    tweak(&mut sim_cfg);
    sim_cfg.align_time = ALIGN;
    sim_cfg.turnaround = Duration::from_micros(args.turnaround_us);
    sim_cfg.adapter = adapter_of(args)?;
    let (sim, host) = match args.line.as_deref() {
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
    let path = match &host {
        Some(_) => PathBuf::from(crate::sim::MEMORY_LINE_PATH),
        None => sim
            .device_path()
            .ok_or_else(|| BenchError::Setup("the simulator has no pty path".into()))?,
    };
    Ok(SimLine { sim, host, path })
}

/// The bench's bus config: the flags' adapter, timing and poll plan.
fn bench_config(
    args: &BenchArgs,
    baud: u32,
    ids: &[u8],
    line: &SimLine,
) -> Result<BusConfig, BenchError> {
    let mut cfg = BusConfig::new("bench", line.path.clone(), baud);
    cfg.ids = ids.to_vec();
    cfg.adapter = AdapterSetting::Fixed(adapter_of(args)?);
    cfg.timing.turnaround_us = args.turnaround_us;
    if args.no_confirm {
        cfg.timing.usb_confirm = false;
    }
    if let Some(spin) = args.reply_spin_us {
        cfg.timing.reply_spin_us = spin;
    }
    if let Some(share) = args.control_share {
        cfg.poll.control_share = share;
    }
    Ok(cfg)
}

/// The bus owner with `cfg` on `line`; every joint online, enabled and
/// aligned.
pub(crate) fn start_bus(
    args: &BenchArgs,
    line: SimLine,
    mut cfg: BusConfig,
    ids: &[u8],
) -> Result<(SimHandle, BusHandle, BusThread), BenchError> {
    if args.no_rt {
        cfg.timing.rt_priority = 0;
    }
    let SimLine { sim, host, .. } = line;
    let (bus, thread) = match (host, sim.pty_opener(cfg.rs485)) {
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

/// The simulator's runner thread at real-time priority: a referee the OS
/// holds back mis-times replies and collisions.
pub(crate) fn referee_realtime() -> Result<(), BenchError> {
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
pub(crate) async fn bring_up(bus: &BusHandle, n: usize) -> Result<(), BenchError> {
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
pub(crate) fn wait_running(sim: &SimHandle, ids: &[u8]) -> Result<(), BenchError> {
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

pub(crate) const CPU_THREADS: [&str; 3] = [THREAD_PREFIX, SIM_THREAD, CLIENT_THREAD];

pub(crate) fn cpu_now() -> Vec<Duration> {
    cpu::snapshot(&CPU_THREADS)
}

pub(crate) fn cpu_share(
    a: &[Duration],
    b: &[Duration],
    s0: &SimStats,
    s1: &SimStats,
    i: usize,
) -> f64 {
    let wall = s1.at.saturating_duration_since(s0.at).as_secs_f64();
    let used = b[i].saturating_sub(a[i]).as_secs_f64();
    used / wall.max(f64::EPSILON)
}
