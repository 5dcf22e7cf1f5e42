//! `jointd sim`: runs a simulated bus on a pseudo-terminal until Ctrl-C,
//! printing the device path as the first line of stdout. Faults can be set
//! by flags at start and switched from stdin while it runs ([`super::console`]).

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use nix::sys::signal::{SigSet, Signal};

use super::{parse_ids, Fault, Firmware, SimConfig, SimError, SimHandle, Simulator};

/// Arguments of `jointd sim`.
#[derive(Args, Debug, Clone)]
pub struct SimArgs {
    /// Device ids, e.g. `1-16` or `1,2,5-7` (duplicates reproduce id conflicts).
    #[arg(long, default_value = "1-16")]
    pub ids: String,
    /// Starting baud of the devices (500000, 230400, 115200, 38400, 19200).
    #[arg(long, default_value_t = 500_000)]
    pub baud: u32,
    /// Request's last byte to reply's first byte, µs.
    #[arg(long, default_value_t = 100)]
    pub turnaround_us: u64,
    /// Encoder alignment after the first enable, ms.
    #[arg(long, default_value_t = 1000)]
    pub align_ms: u64,
    /// Power-up to the spontaneous INFO_01, ms.
    #[arg(long, default_value_t = 5)]
    pub boot_ms: u64,
    /// Keeps flash (ids, parameters) across runs, as JSON.
    #[arg(long)]
    pub state_file: Option<PathBuf>,
    /// Probability that each byte on the line is garbled.
    #[arg(long, default_value_t = 0.0)]
    pub corrupt_rate: f64,
    /// Probability that a reply is lost.
    #[arg(long, default_value_t = 0.0)]
    pub drop_rate: f64,
    /// Added to every turnaround, µs.
    #[arg(long, default_value_t = 0)]
    pub extra_turnaround_us: u64,
    /// Devices blocked by an obstacle where they stand, e.g. `--stall 3 --stall 4`.
    #[arg(long)]
    pub stall: Vec<u8>,
    /// A mechanical end stop: `ID=DEG` (output degrees of the factory
    /// zero), e.g. `--hard-stop 1=-40`; the joint cannot pass it.
    #[arg(long, value_name = "ID=DEG")]
    pub hard_stop: Vec<String>,
    /// An elastic object a finger closes on: `ID=DEG:NM_PER_DEG` (contact
    /// angle in output degrees of the factory zero, stiffness in N·m per
    /// degree pressed in), e.g. `--object 2=30:0.05`; repeatable.
    #[arg(long, value_name = "ID=DEG:NM_PER_DEG")]
    pub object: Vec<String>,
    /// Devices whose supply sags below the under-voltage level.
    #[arg(long)]
    pub under_voltage: Vec<u8>,
    /// Protocol revision of the devices' firmware: `2.0.1`, `2.0.8`, or per
    /// id, e.g. `1-8=2.0.8,9-16=2.0.1` (ids not named run 2.0.1).
    #[arg(long, value_name = "SPEC", default_value = "2.0.1")]
    pub firmware: String,
    /// The USB adapter between the host and the wire: `native` (none),
    /// `ftdi[:MS]` (latency timer, default 16), `ch340`, `cp2102`, `ft232h[:MS]`.
    #[arg(long, value_name = "MODEL", default_value = "native")]
    pub adapter: String,
    /// Host writes reach the adapter late by a random delay with these
    /// quantiles, µs: `P50,P99,MAX` or `P50,P99,P99.9,MAX`, e.g.
    /// `38,150,750,1000` (a busy host or USB hub). Needs `--adapter`.
    #[arg(long, value_name = "P50,P99[,P99.9],MAX")]
    pub write_delay_us: Option<String>,
    /// The adapter echoes every host frame back to the host (its receiver
    /// stays on while it sends), as some USB-RS485 adapters do.
    #[arg(long)]
    pub echo: bool,
    /// The adapter's driver count of unsent bytes (`TIOCOUTQ`) never falls,
    /// though the bytes go out. Needs `--adapter` (a native line has no
    /// count); seen only by a port opened in this process.
    #[arg(long)]
    pub stuck_count: bool,
    /// Seed of noise and fault dice.
    #[arg(long, default_value_t = super::config::DEFAULT_SEED)]
    pub seed: u64,
    /// Run the simulator thread under SCHED_FIFO when permitted (tighter timing).
    #[arg(long)]
    pub realtime: bool,
    /// Instead of serving: poll the first device N times over a pty and print
    /// real-vs-model timing errors (µs percentiles) as JSON.
    #[arg(long, value_name = "N")]
    pub measure: Option<usize>,
}

impl SimArgs {
    pub fn config(&self) -> Result<SimConfig, SimError> {
        let mut cfg = SimConfig::new(parse_ids(&self.ids)?, self.baud);
        cfg.turnaround = Duration::from_micros(self.turnaround_us);
        cfg.align_time = Duration::from_millis(self.align_ms);
        cfg.boot_delay = Duration::from_millis(self.boot_ms);
        cfg.state_file = self.state_file.clone();
        cfg.seed = self.seed;
        cfg.realtime = self.realtime;
        cfg.firmware = Firmware::parse(&self.firmware)?;
        cfg.adapter = super::AdapterModel::parse(&self.adapter).map_err(SimError::BadAdapter)?;
        cfg.write_delay = parse_write_delay(self.write_delay_us.as_deref())?;
        cfg.echo = self.echo;
        cfg.stuck_count = self.stuck_count;
        cfg.hard_stops = self
            .hard_stop
            .iter()
            .map(|s| parse_hard_stop(s))
            .collect::<Result<_, _>>()?;
        cfg.objects = self
            .object
            .iter()
            .map(|s| parse_object(s))
            .collect::<Result<_, _>>()?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The faults the flags ask for, applied at start.
    pub fn faults(&self) -> Vec<Fault> {
        let mut faults = Vec::new();
        if self.corrupt_rate > 0.0 {
            faults.push(Fault::CorruptRate(self.corrupt_rate));
        }
        if self.drop_rate > 0.0 {
            faults.push(Fault::DropReplies {
                dev_id: None,
                rate: self.drop_rate,
            });
        }
        if self.extra_turnaround_us > 0 {
            faults.push(Fault::ExtraTurnaround(Duration::from_micros(
                self.extra_turnaround_us,
            )));
        }
        faults.extend(self.stall.iter().map(|&dev_id| Fault::Stall {
            dev_id,
            at_deg: None,
        }));
        faults.extend(
            self.under_voltage
                .iter()
                .map(|&dev_id| Fault::UnderVoltage { dev_id, on: true }),
        );
        faults
    }
}

/// `--write-delay-us`, when given.
pub fn parse_write_delay(spec: Option<&str>) -> Result<Option<super::WriteDelay>, SimError> {
    spec.map(super::WriteDelay::parse)
        .transpose()
        .map_err(SimError::BadWriteDelay)
}

/// `ID=DEG`: a device id and a finite angle within the device's range.
pub fn parse_hard_stop(spec: &str) -> Result<(u8, f64), SimError> {
    let bad =
        |why: &str| SimError::BadHardStop(format!("`{spec}`: {why} (expected ID=DEG, e.g. 1=-40)"));
    let (id, deg) = spec.split_once('=').ok_or_else(|| bad("no `=`"))?;
    let id: u8 = id
        .trim()
        .parse()
        .map_err(|_| bad("the id is not a number"))?;
    let deg: f64 = deg
        .trim()
        .parse()
        .map_err(|_| bad("the angle is not a number"))?;
    if !deg.is_finite() || deg.abs() > crate::protocol::units::MAX_ANGLE_DEG {
        return Err(bad("the angle is outside ±255°"));
    }
    Ok((id, deg))
}

/// `ID=DEG:NM_PER_DEG`: a device id, a contact angle within the device's
/// range and a stiffness above 0 (N·m per degree).
pub fn parse_object(spec: &str) -> Result<super::SimObject, SimError> {
    let bad = |why: &str| {
        SimError::BadObject(format!(
            "`{spec}`: {why} (expected ID=DEG:NM_PER_DEG, e.g. 2=30:0.05)"
        ))
    };
    let (id, rest) = spec.split_once('=').ok_or_else(|| bad("no `=`"))?;
    let (deg, k) = rest.split_once(':').ok_or_else(|| bad("no `:`"))?;
    let id: u8 = id
        .trim()
        .parse()
        .map_err(|_| bad("the id is not a number"))?;
    let at_deg: f64 = deg
        .trim()
        .parse()
        .map_err(|_| bad("the angle is not a number"))?;
    let nm_per_deg: f64 = k
        .trim()
        .parse()
        .map_err(|_| bad("the stiffness is not a number"))?;
    if !at_deg.is_finite() || at_deg.abs() > crate::protocol::units::MAX_ANGLE_DEG {
        return Err(bad("the angle is outside ±255°"));
    }
    if !nm_per_deg.is_finite() || nm_per_deg <= 0.0 {
        return Err(bad("the stiffness must be above 0 N·m/°"));
    }
    Ok(super::SimObject {
        id,
        at_deg,
        nm_per_deg,
    })
}

/// Runs the simulator until SIGINT/SIGTERM; prints the path first, stats last (stderr).
pub fn run(args: &SimArgs) -> Result<(), SimError> {
    let cfg = args.config()?;
    if let Some(polls) = args.measure {
        let report = super::measure::run(cfg, polls)?;
        println!(
            "{}",
            serde_json::to_string_pretty(&report).unwrap_or_default()
        );
        return Ok(());
    }
    // Block the signals before the simulator thread exists so only sigwait sees them.
    let mut signals = SigSet::empty();
    signals.add(Signal::SIGINT);
    signals.add(Signal::SIGTERM);
    signals
        .thread_block()
        .map_err(|e| SimError::Pty(e.into()))?;
    let sim = Simulator::spawn_pty(cfg)?;
    apply_faults(&sim, &args.faults());
    let path = sim.device_path().unwrap_or_default();
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{}", path.display());
    let _ = out.flush();
    drop(out);
    super::console::spawn(sim.clone());
    let _ = signals.wait();
    let stats = sim.stats();
    sim.shutdown();
    eprintln!("{}", serde_json::to_string(&stats).unwrap_or_default());
    Ok(())
}

fn apply_faults(sim: &SimHandle, faults: &[Fault]) {
    for f in faults {
        sim.inject(*f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_object_parses_and_a_bad_one_says_what_is_wrong() {
        let ob = parse_object("2=30.5:0.05").unwrap();
        assert_eq!((ob.id, ob.at_deg, ob.nm_per_deg), (2, 30.5, 0.05));
        for (bad, why) in [
            ("2=30", "no `:`"),
            ("2:30:1", "no `=`"),
            ("x=1:1", "id"),
            ("2=300:0.1", "±255"),
            ("2=30:0", "above 0"),
            ("2=30:-1", "above 0"),
        ] {
            let e = parse_object(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
