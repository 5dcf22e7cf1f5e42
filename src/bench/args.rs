//! `jointd bench`'s flags, what can go wrong, and the simulator's thread name.

use clap::Args;
use thiserror::Error;

use crate::bus::BusError;
use crate::sim::SimError;

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
    /// Hold the doctor to its word: `jointd doctor` examines the simulated
    /// bus, the bus then runs the config it proposed under the load, and
    /// the rates measured must be within 5 % of the ones it predicted.
    #[arg(long)]
    pub doctor: bool,
}

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

/// Thread name prefix of the simulator's runner.
pub(crate) const SIM_THREAD: &str = "jointd-sim";
