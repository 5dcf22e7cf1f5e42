//! One workload's result, checked against the engine's targets and printed.

use std::fmt;
use std::time::Duration;

use crate::bus::handle::{BusCounters, BusRates};

use super::analysis::Analysis;

/// The engine's targets at 500000 baud; rates scale with the baud.
const REFERENCE_BAUD: f64 = 500_000.0;
const MIN_OCCUPANCY: f64 = 0.95;
const MIN_CONTROL_HZ: f64 = 400.0;
const MIN_TELEMETRY_HZ: f64 = 40.0;
const MAX_P99_US: u64 = 3_000;
const MAX_DAEMON_CPU: f64 = 0.15;
/// Behind a USB adapter, each rate as a share of the adapter's
/// pipeline bound.
const MIN_SHARE_OF_BOUND: f64 = 0.9;
/// With late writes: control as a share of the bound, and how long the
/// pipeline has to back off before the wire must be clean.
const MIN_SHARE_LATE: f64 = 0.8;
const BACKOFF_ALLOWANCE_S: usize = 2;

#[derive(Debug)]
pub struct Report {
    pub baud: u32,
    /// The adapter the bus sat behind, and the devices' turnaround: what
    /// the bounds below follow from.
    pub adapter: crate::sim::AdapterModel,
    pub turnaround: Duration,
    pub joints: usize,
    pub rate_hz: u32,
    pub warmup: Duration,
    pub occupancy: f64,
    pub collisions: u64,
    /// Host writes late by this distribution from the window's start.
    pub write_delay: Option<crate::sim::WriteDelay>,
    /// Behind a USB adapter: the collisions in each second of the window.
    pub collisions_by_second: Vec<u64>,
    /// The pipeline's mode at the end of each of those seconds.
    pub modes_by_second: Vec<&'static str>,
    /// Writes the delay made miss their USB frame (the referee's count).
    pub slipped_writes: u64,
    /// The bus's USB pipeline at the end of the run.
    pub pipeline: Option<crate::bus::usb::guard::UsbPipelineView>,
    pub analysis: Analysis,
    /// Share of one core over the window: bus owner, simulator, client.
    pub cpu_owner: f64,
    pub cpu_sim: f64,
    pub cpu_client: f64,
    /// The daemon's own statistics at the end of the window.
    pub daemon: BusRates,
    /// How late the simulator delivered replies against its own model, µs
    /// (p50, p99): the referee's precision on this machine.
    pub referee_late_us: [f64; 2],
    /// Host writes the adapter model found waiting after a stall of the
    /// simulator's thread (dated to the earliest they may have been written).
    pub referee_undated: u64,
    /// With `--pty-lag`: the lag of a pty of the probe's own beside the run.
    pub pty_lag: Option<super::pty_lag::PtyLag>,
    /// The daemon's counters at the end of the run (warm-up included):
    /// behind a latent adapter, how the USB pipeline wrote.
    pub counters: BusCounters,
}

impl Report {
    fn scale(&self) -> f64 {
        f64::from(self.baud) / REFERENCE_BAUD
    }

    /// Every target, scaled for the baud: (what, met). Behind a USB adapter
    /// the rates are judged against its pipeline bound instead.
    pub fn checks(&self) -> Vec<(String, bool)> {
        if self.adapter.is_latent() {
            return self.adapter_checks();
        }
        let a = &self.analysis;
        let control = MIN_CONTROL_HZ * self.scale();
        let telemetry = MIN_TELEMETRY_HZ * self.scale();
        vec![
            (
                format!("occupancy >= {MIN_OCCUPANCY}"),
                self.occupancy >= MIN_OCCUPANCY,
            ),
            ("zero collisions".into(), self.collisions == 0),
            (
                format!("control >= {control:.1}/s every joint"),
                Analysis::min_rate(&a.control_hz) >= control,
            ),
            (
                format!("telemetry >= {telemetry:.1}/s every joint"),
                Analysis::min_rate(&a.telemetry_hz) >= telemetry,
            ),
            (
                format!("setpoint-to-wire p99 <= {} ms", MAX_P99_US / 1000),
                a.latency_us(0.99) <= MAX_P99_US,
            ),
            (
                format!("daemon CPU <= {:.0} %", MAX_DAEMON_CPU * 100.0),
                self.cpu_owner <= MAX_DAEMON_CPU,
            ),
        ]
    }

    /// Control and telemetry per joint (the slowest joint) as shares of the
    /// adapter's bound: `T = P·⌈((B + 2)·tf + ta)/P⌉` with B = 2.
    pub(super) fn shares_of_bound(&self) -> (f64, f64) {
        let frame = Duration::from_secs_f64(200.0 / f64::from(self.baud));
        let cycle = self.adapter.cycle_bound(frame, self.turnaround, 2);
        let per_s = 1.0 / cycle.as_secs_f64().max(f64::EPSILON);
        let a = &self.analysis;
        let joints = self.joints.max(1) as f64;
        (
            Analysis::min_rate(&a.control_hz) / per_s,
            Analysis::min_rate(&a.telemetry_hz) / (per_s / joints),
        )
    }

    /// Collisions after the first [`BACKOFF_ALLOWANCE_S`] seconds of the window.
    fn collisions_after_allowance(&self) -> u64 {
        self.collisions_by_second
            .iter()
            .skip(BACKOFF_ALLOWANCE_S)
            .sum()
    }

    /// Collisions in the seconds after the one the pipeline first backed
    /// off in (all of them if it never did).
    fn collisions_after_backoff(&self) -> u64 {
        let first = self
            .modes_by_second
            .iter()
            .position(|m| *m != "pipelined" && *m != "none")
            .map_or(0, |i| i + 1);
        self.collisions_by_second.iter().skip(first).sum()
    }

    fn adapter_checks(&self) -> Vec<(String, bool)> {
        let (control, telemetry) = self.shares_of_bound();
        if self.write_delay.is_some() {
            return vec![
                (
                    "zero collisions in the seconds after the pipeline backed off".into(),
                    self.collisions_after_backoff() == 0,
                ),
                (
                    format!(
                        "zero collisions after the first {BACKOFF_ALLOWANCE_S} s \
                         (misses when the first late write comes later)"
                    ),
                    self.collisions_after_allowance() == 0,
                ),
                (
                    format!("control >= {MIN_SHARE_LATE} of the bound every joint"),
                    control >= MIN_SHARE_LATE,
                ),
                (
                    "telemetry from every joint".into(),
                    Analysis::min_rate(&self.analysis.telemetry_hz) > 0.0,
                ),
            ];
        }
        vec![
            ("zero collisions".into(), self.collisions == 0),
            (
                format!("control >= {MIN_SHARE_OF_BOUND} of the bound every joint"),
                control >= MIN_SHARE_OF_BOUND,
            ),
            (
                format!("telemetry >= {MIN_SHARE_OF_BOUND} of the bound every joint"),
                telemetry >= MIN_SHARE_OF_BOUND,
            ),
            (
                format!("setpoint-to-wire p99 <= {} ms", MAX_P99_US / 1000),
                self.analysis.latency_us(0.99) <= MAX_P99_US,
            ),
            (
                format!("daemon CPU <= {:.0} %", MAX_DAEMON_CPU * 100.0),
                self.cpu_owner <= MAX_DAEMON_CPU,
            ),
        ]
    }

    pub fn passed(&self) -> bool {
        self.checks().iter().all(|(_, ok)| *ok)
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "== {} joints at {} baud, client streaming all targets at {} Hz; \
             {:.1} s measured after {:.1} s warm-up",
            self.joints,
            self.baud,
            self.rate_hz,
            self.analysis.window.as_secs_f64(),
            self.warmup.as_secs_f64()
        )?;
        let rows = self.result_rows().into_iter().chain(self.bound_rows());
        for (label, value) in rows.chain(self.context_rows()) {
            writeln!(f, "  {label:<36}{value}")?;
        }
        for (what, ok) in self.checks() {
            writeln!(f, "  [{}] {what}", if ok { "ok" } else { "FAIL" })?;
        }
        Ok(())
    }
}
