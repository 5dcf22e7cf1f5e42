//! The report's rows: what was measured against its targets, against the
//! adapter's bound, and where the wire time went.

use std::collections::BTreeMap;
use std::time::Duration;

use super::analysis::{quantile, Analysis};
use super::report::Report;

impl Report {
    /// The measured quantities that have targets.
    pub(super) fn result_rows(&self) -> Vec<(&'static str, String)> {
        let a = &self.analysis;
        let rates = |m: &BTreeMap<u8, f64>| {
            let max = m.values().copied().fold(0.0, f64::max);
            let (min, mean) = (Analysis::min_rate(m), Analysis::mean_rate(m));
            format!("min {min:7.1}  mean {mean:7.1}  max {max:7.1}")
        };
        let (p50, p99, max) = (a.latency_us(0.5), a.latency_us(0.99), a.latency_us(1.0));
        vec![
            (
                "wire occupancy (simulator referee)",
                format!("{:.4}", self.occupancy),
            ),
            ("collisions", self.collisions.to_string()),
            ("control updates/s per joint", rates(&a.control_hz)),
            ("telemetry samples/s per joint", rates(&a.telemetry_hz)),
            (
                "setpoint-to-wire latency",
                format!(
                    "p50 {:.2} ms  p99 {:.2} ms  max {:.2} ms  ({} of {} joint-writes carried; \
                     the rest were superseded before a frame was due)",
                    ms(p50),
                    ms(p99),
                    ms(max),
                    a.latencies_us.len(),
                    a.written
                ),
            ),
            (
                "daemon CPU (bus owner thread)",
                format!(
                    "{:.1} % of one core   [simulator thread {:.1} %, client thread {:.1} %]",
                    self.cpu_owner * 100.0,
                    self.cpu_sim * 100.0,
                    self.cpu_client * 100.0
                ),
            ),
        ]
    }

    /// The cycle of two broadcasts and a poll this adapter allows (the
    /// pipeline bound `T = P·⌈((B + 2)·tf + ta) / P⌉`, the wire alone on
    /// native), and the measured rates as shares of what it gives: control
    /// `1/T` updates/s per joint (two broadcasts carry all 16), telemetry
    /// `1/(T·joints)` per joint.
    pub(super) fn bound_rows(&self) -> Vec<(&'static str, String)> {
        let frame = Duration::from_secs_f64(200.0 / f64::from(self.baud));
        let cycle = self.adapter.cycle_bound(frame, self.turnaround, 2);
        let per_s = 1.0 / cycle.as_secs_f64().max(f64::EPSILON);
        let joints = self.joints.max(1) as f64;
        let (control, telemetry) = self.shares_of_bound();
        vec![(
            "against the adapter's bound",
            format!(
                "{}: cycle {:.0} µs -> control {:.0}/s, telemetry {:.1}/s per joint; measured control {:.2}, telemetry {:.2} of it",
                self.adapter,
                cycle.as_secs_f64() * 1e6,
                per_s,
                per_s / joints,
                control,
                telemetry,
            ),
        )]
    }

    /// Where the wire time went, and how precise the referee was.
    pub(super) fn context_rows(&self) -> Vec<(&'static str, String)> {
        let a = &self.analysis;
        let secs = a.window.as_secs_f64().max(f64::EPSILON);
        let per_s = |n: u64| n as f64 / secs;
        let gaps = |v: &[u64]| {
            let share = v.iter().sum::<u64>() as f64 / 1e4 / secs;
            let (p50, p99) = (quantile(v, 0.5), quantile(v, 0.99));
            format!(
                "{} gaps, p50 {p50} µs, p99 {p99} µs, {share:.1} % of the time",
                v.len()
            )
        };
        let d = &self.daemon;
        let mut rows = vec![
            (
                "host frames/s on the wire",
                format!(
                    "broadcast {:.0}  control {:.0}  poll {:.0}",
                    per_s(a.broadcasts),
                    per_s(a.control_frames),
                    per_s(a.polls)
                ),
            ),
            ("idle line after a reply", gaps(&a.idle_after_reply_us)),
            ("idle line after a host frame", gaps(&a.idle_after_host_us)),
            (
                "referee's reply delivery vs model",
                format!(
                    "p50 {:.1} µs late, p99 {:.1} µs late",
                    self.referee_late_us[0], self.referee_late_us[1]
                ),
            ),
            (
                "referee's undated host writes",
                format!(
                    "{} (after a stall of its thread of over 100 µs)",
                    self.referee_undated
                ),
            ),
            (
                "the daemon's own view (last 1 s)",
                format!(
                    "utilisation {:.3}  timeouts/s {:.1}  reply timeout {:.1} ms  \
                     wake lead {} µs  reply lag {} µs  setpoint age p50 {:.2} ms p99 {:.2} ms",
                    d.wire_utilisation,
                    d.timeouts_per_s,
                    ms(d.reply_timeout_us),
                    d.wake_lead_us,
                    d.reply_lag_us,
                    ms(d.setpoint_age_p50_us),
                    ms(d.setpoint_age_p99_us)
                ),
            ),
        ];
        self.probe_rows(&mut rows);
        self.usb_rows(&mut rows);
        rows
    }

    /// The probes beside the run: the pty's own lag, the write delay.
    fn probe_rows(&self, rows: &mut Vec<(&'static str, String)>) {
        if let Some(lag) = &self.pty_lag {
            let us = |d: Duration| d.as_micros();
            rows.push((
                "pty lag beside the run (probe)",
                format!(
                    "p50 {} µs  p99 {} µs  p99.9 {} µs  max {} µs; {} of {} writes over {} ms",
                    us(lag.quantile(0.5)),
                    us(lag.quantile(0.99)),
                    us(lag.quantile(0.999)),
                    us(lag.max()),
                    lag.late(),
                    lag.lags.len(),
                    super::pty_lag::LATE.as_millis()
                ),
            ));
        }
        if let Some(delay) = &self.write_delay {
            rows.push((
                "write delay (from the window's start)",
                format!(
                    "p50,p99,p99.9,max {delay} µs; {} writes slipped a USB frame",
                    self.slipped_writes
                ),
            ));
        }
    }

    /// Behind a USB adapter: collisions and the pipeline's mode each second,
    /// the pipeline at the end and over the whole run.
    fn usb_rows(&self, rows: &mut Vec<(&'static str, String)>) {
        if !self.collisions_by_second.is_empty() {
            let by_s = &self.collisions_by_second;
            let last3: u64 = by_s.iter().rev().take(3).sum();
            rows.push((
                "collisions each second",
                format!(
                    "{by_s:?}: first second {}, last 3 s {last3} ({:.1}/s)",
                    by_s.first().copied().unwrap_or(0),
                    last3 as f64 / 3.0_f64.min(by_s.len().max(1) as f64)
                ),
            ));
            rows.push((
                "pipeline mode each second",
                format!("{:?}", self.modes_by_second),
            ));
        }
        if let Some(p) = &self.pipeline {
            rows.push((
                "USB pipeline at the end",
                format!(
                    "{}{} (guard {} µs, writes {} µs before their frame); {} writes taken late, \
                     {} counts given up; {} backoffs, \
                     {} recoveries; {} of {} sentinels late, {} late writes backed off; \
                     last change: {}",
                    p.mode,
                    if p.confirming { ", confirmed" } else { "" },
                    p.guard_us,
                    p.lead_us,
                    p.writes_taken_late,
                    p.counts_given_up,
                    p.backoffs,
                    p.recoveries,
                    p.sentinels_late,
                    p.sentinels,
                    p.late_writes,
                    p.reason
                ),
            ));
        }
        if self.adapter.is_latent() {
            let c = &self.counters;
            rows.push((
                "USB pipeline (whole run)",
                format!(
                    "{} polls written blind: {} before the frame clock was known, \
                     {} held for a later frame",
                    c.polls_pipelined, c.usb_writes_unclocked, c.usb_writes_ambiguous
                ),
            ));
        }
    }
}

fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}
