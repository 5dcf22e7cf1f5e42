//! Starting the buses: the simulator of `--sim` and the config of the bus
//! that reaches it, then one owner per bus; the live Foxglove view's
//! server, bound before them; and the open-files limit the connections
//! need.

use std::collections::BTreeMap;
use std::path::PathBuf;

use super::args::SIM_BUS_NAME;
use super::error::DaemonError;
use super::plan::Plan;
use crate::bus::{spawn_bus, spawn_bus_on, spawn_bus_with, AdapterSetting, BusConfig, BusHandle};
use crate::foxglove::LiveView;
use crate::sim::{SimConfig, SimHandle, Simulator};
use crate::transport::{Opener, Transport};

/// Reply slack of the `--sim` bus, µs (see [`crate::bus::Timing`]).
const SIM_REPLY_MARGIN_US: u64 = 20_000;

/// A bus to start, and how it reaches its port.
type BusToStart = (BusConfig, Port);

/// How a bus reaches its port: a tty at its configured path, the
/// simulator's pty through the opener it gives, or the simulator's
/// in-memory line, handed in (there is no path to open).
enum Port {
    Path,
    Opened(Opener),
    HandedIn(Box<dyn Transport>),
}

/// Starts the simulator of `--sim` and the config of the bus that reaches
/// it: over a pty, opened by path like hardware; behind a USB adapter
/// model, over the in-memory line instead, with the line itself
/// ([`Simulator::spawn_for`] says why).
fn start_sim(sim_cfg: SimConfig) -> Result<(SimHandle, BusToStart), DaemonError> {
    let (ids, baud, joints) = (sim_cfg.ids.clone(), sim_cfg.baud, sim_cfg.ids.len());
    let firmware = sim_cfg.firmware.to_string();
    let adapter = sim_cfg.adapter;
    let (sim, memory) = Simulator::spawn_for(sim_cfg)?;
    // The path is the simulator's, set below; the rest as any bus's.
    let mut cfg = BusConfig::new(SIM_BUS_NAME, PathBuf::new(), baud);
    let (path, port) = match (memory, sim.device_path(), sim.pty_opener(cfg.rs485)) {
        (Some(host), _, _) => (
            PathBuf::from(crate::sim::MEMORY_LINE_PATH),
            Port::HandedIn(Box::new(host)),
        ),
        (None, Some(path), Some(opener)) => (path, Port::Opened(opener)),
        _ => {
            return Err(DaemonError::Io {
                what: "simulator".into(),
                source: std::io::Error::other("the simulator has no device path"),
            })
        }
    };
    tracing::info!(path = %path.display(), joints, baud, %firmware, %adapter, "simulated bus started");
    cfg.path = path;
    cfg.ids = ids;
    // Neither a pty nor the in-memory line shows USB in sysfs: the bus is
    // told what the simulator models.
    cfg.adapter = AdapterSetting::Fixed(adapter);
    // The simulator shares the CPU with the daemon: on a busy machine its
    // replies can come milliseconds late, which is not a silent device.
    cfg.timing.reply_margin_us = SIM_REPLY_MARGIN_US;
    Ok((sim, (cfg, port)))
}

/// Every connection holds a file descriptor: at the common soft limit of
/// 1024 about a thousand idle connections leave no descriptor to accept the
/// e-stop's. The soft limit goes up to the hard one (what the service
/// manager allows); failing that is only logged.
pub(super) fn raise_open_files_limit() {
    use nix::sys::resource::{getrlimit, setrlimit, Resource};
    match getrlimit(Resource::RLIMIT_NOFILE) {
        Ok((soft, hard)) if soft < hard => match setrlimit(Resource::RLIMIT_NOFILE, hard, hard) {
            Ok(()) => tracing::debug!(from = soft, to = hard, "open files limit raised"),
            Err(e) => tracing::warn!(soft, hard, "open files limit not raised: {e}"),
        },
        Ok(_) => {}
        Err(e) => tracing::warn!("open files limit not read: {e}"),
    }
}

/// Starts one owner per bus; a port that is not there yet is retried by its owner.
fn start_buses(
    configs: Vec<BusToStart>,
) -> Result<(Vec<BusHandle>, Vec<crate::bus::BusThread>), DaemonError> {
    let mut handles = Vec::with_capacity(configs.len());
    let mut threads = Vec::with_capacity(configs.len());
    for (cfg, port) in configs {
        tracing::info!(bus = %cfg.name, path = %cfg.path.display(), baud = cfg.baud, "starting bus");
        let (handle, thread) = match port {
            Port::Path => spawn_bus(cfg)?,
            Port::Opened(opener) => spawn_bus_with(cfg, opener)?,
            Port::HandedIn(port) => spawn_bus_on(cfg, port)?,
        };
        handles.push(handle);
        threads.push(thread);
    }
    Ok((handles, threads))
}

/// The buses as started: the simulator (kept alive until shutdown), one
/// handle and one owner thread per bus, the devices each was configured
/// with (the ones the daemon manages).
pub(super) struct Started {
    pub(super) sim: Option<SimHandle>,
    pub(super) handles: Vec<BusHandle>,
    pub(super) threads: Vec<crate::bus::BusThread>,
    pub(super) managed: BTreeMap<String, Vec<u8>>,
}

/// The configured buses and the simulator's, each with its owner.
pub(super) fn start_all(
    buses: Vec<BusConfig>,
    sim: Option<SimConfig>,
) -> Result<Started, DaemonError> {
    let mut configs: Vec<BusToStart> = buses.into_iter().map(|cfg| (cfg, Port::Path)).collect();
    let sim = match sim {
        Some(sim_cfg) => {
            let (sim, bus) = start_sim(sim_cfg)?;
            configs.push(bus);
            Some(sim)
        }
        None => None,
    };
    let managed = configs
        .iter()
        .map(|(cfg, _)| (cfg.name.clone(), cfg.ids.clone()))
        .collect();
    let (handles, threads) = start_buses(configs)?;
    Ok(Started {
        sim,
        handles,
        threads,
        managed,
    })
}

/// The live Foxglove view of `--foxglove` (none when off), listening with
/// the channels of every bus the plan starts: bound before any bus opens,
/// as the API's listener, so a taken address stops the daemon there.
pub(super) async fn bind_live(plan: &Plan) -> Result<Option<LiveView>, DaemonError> {
    let (Some(addr), Some(stats)) = (plan.foxglove, plan.control.foxglove.clone()) else {
        return Ok(None);
    };
    let buses: Vec<String> = plan
        .buses
        .iter()
        .map(|b| b.name.clone())
        .chain(plan.sim.as_ref().map(|_| SIM_BUS_NAME.to_owned()))
        .collect();
    let live = LiveView::bind(addr, &buses, stats).await?;
    let url = format!("ws://{}", live.addr());
    tracing::info!(%url, "Foxglove live view: in the Foxglove app, open a connection to the url");
    if !addr.ip().is_loopback() {
        tracing::warn!(
            %url,
            "the Foxglove live view listens beyond this host and Foxglove's protocol has no \
             authentication: whoever reaches it sees every bus's joints, frames, setpoints and \
             events (read only). For remote use, keep it on loopback and tunnel it over SSH \
             (docs/foxglove.md)"
        );
    }
    Ok(Some(live))
}
