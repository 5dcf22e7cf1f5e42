//! The WebSocket bench's report: a column per phase, the send floor, and
//! the checks against the goals (each with its margin).

use std::fmt::Write as _;

use super::phase::Phase;
use crate::bench::analysis::Analysis;
use crate::bench::args::BenchArgs;
use crate::bench::rig::load_average;
use crate::bench::send_floor;

/// The bounds the WebSocket path is held to: its cost and load tolerance.
const MAX_WS_COST_US: f64 = 500.0;
const MAX_P99_US: u64 = 3000;
const MAX_CHANGE: f64 = 0.10;

pub(super) fn report(
    args: &BenchArgs,
    baud: u32,
    p: &[Phase; 3],
    floor: Option<send_floor::SendFloor>,
) -> (String, bool) {
    let mut out = header(args, baud);
    let row = |out: &mut String, what: &str, f: &dyn Fn(&Phase) -> String| {
        let _ = writeln!(
            out,
            "  {what:<44} {:>16} {:>16} {:>22}",
            f(&p[0]),
            f(&p[1]),
            f(&p[2])
        );
    };
    row(&mut out, "wire occupancy (referee)", &|x| {
        format!("{:.3}", x.occupancy)
    });
    row(&mut out, "collisions", &|x| x.collisions.to_string());
    row(&mut out, "control updates/s per joint (min)", &|x| {
        format!("{:.0}", Analysis::min_rate(&x.analysis.control_hz))
    });
    row(&mut out, "telemetry samples/s per joint (min)", &|x| {
        format!("{:.1}", Analysis::min_rate(&x.analysis.telemetry_hz))
    });
    row(&mut out, "setpoint-to-wire p50 / p99, µs", &|x| {
        format!(
            "{} / {}",
            x.analysis.latency_us(0.5),
            x.analysis.latency_us(0.99)
        )
    });
    row(&mut out, "daemon CPU (bus owner + HTTP/WS), % core", &|x| {
        format!("{:.1}", x.cpu_daemon * 100.0)
    });
    row(&mut out, "client threads CPU, % core", &|x| {
        format!("{:.1}", x.cpu_clients * 100.0)
    });
    row(&mut out, "process RSS (daemon+sim+clients), MiB", &|x| {
        format!("{:.1}", x.rss_mb)
    });
    row(&mut out, "telemetry msgs/s per client min / mean", &|x| {
        x.telemetry
            .map_or("-".into(), |(min, mean, _)| format!("{min:.0} / {mean:.0}"))
    });
    row(&mut out, "telemetry samples skipped (all clients)", &|x| {
        x.telemetry.map_or("-".into(), |(_, _, d)| d.to_string())
    });
    if let (Some(f), Some(len)) = (floor, p[2].telemetry_len) {
        floor_lines(&mut out, args, p, &f, len);
    }
    let (checks, passed) = checks(&p[0], &p[1], &p[2]);
    for (what, ok) in checks {
        let _ = writeln!(out, "  [{}] {what}", if ok { "ok" } else { "MISS" });
    }
    (out, passed)
}

/// The report's first lines: the run, then the phases' column heads.
fn header(args: &BenchArgs, baud: u32) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "WebSocket bench: {} joints at {baud} baud, every target at {} Hz; {:.0} s per phase after {:.0} s warm-up; load average {}",
        args.joints, args.rate_hz, args.seconds, args.warmup, load_average());
    let _ = writeln!(
        out,
        "  {:<44} {:>16} {:>16} {:>22}",
        "", "engine alone", "WebSocket", "WS + telemetry"
    );
    out
}

/// What the telemetry sends cost alone, and the floor they put under the
/// WS + telemetry phase.
fn floor_lines(
    out: &mut String,
    args: &BenchArgs,
    p: &[Phase; 3],
    f: &send_floor::SendFloor,
    len: f64,
) {
    let _ = writeln!(
        out,
        "  sends alone: {} loopback connections at {} Hz, {len:.0} B each ({:.0} sends/s), one thread doing nothing else: {:.1} % core",
        args.telemetry_clients, args.telemetry_hz, f.sends_per_s, f.sender_cpu * 100.0
    );
    let _ = writeln!(
        out,
        "  floor of WS + telemetry: the WebSocket phase {:.1} % + the sends {:.1} % = {:.1} % core (measured {:.1} %)",
        p[1].cpu_daemon * 100.0,
        f.sender_cpu * 100.0,
        (p[1].cpu_daemon + f.sender_cpu) * 100.0,
        p[2].cpu_daemon * 100.0
    );
}

fn change(a: f64, b: f64) -> f64 {
    if a == 0.0 {
        0.0
    } else {
        (b - a) / a
    }
}

fn checks(engine: &Phase, ws: &Phase, loaded: &Phase) -> (Vec<(String, bool)>, bool) {
    let (e50, e99) = (
        engine.analysis.latency_us(0.5) as f64,
        engine.analysis.latency_us(0.99) as f64,
    );
    let (w50, w99) = (
        ws.analysis.latency_us(0.5) as f64,
        ws.analysis.latency_us(0.99) as f64,
    );
    let figures = |x: &Phase| {
        [
            ("occupancy", x.occupancy),
            (
                "min control rate",
                Analysis::min_rate(&x.analysis.control_hz),
            ),
            (
                "min telemetry rate",
                Analysis::min_rate(&x.analysis.telemetry_hz),
            ),
        ]
    };
    let mut list = vec![
        (
            format!("WebSocket p99 {w99:.0} µs <= {MAX_P99_US} µs"),
            ws.analysis.latency_us(0.99) <= MAX_P99_US,
        ),
        (
            format!(
                "WebSocket path cost p50 {:.0} µs, p99 {:.0} µs <= {MAX_WS_COST_US} µs",
                w50 - e50,
                w99 - e99
            ),
            w99 - e99 <= MAX_WS_COST_US,
        ),
        (
            format!(
                "no collisions ({} / {} / {})",
                engine.collisions, ws.collisions, loaded.collisions
            ),
            engine.collisions + ws.collisions + loaded.collisions == 0,
        ),
    ];
    for ((what, a), (_, b)) in figures(ws).into_iter().zip(figures(loaded)) {
        let c = change(a, b);
        list.push((
            format!("{what} with telemetry clients: {:+.1} %", c * 100.0),
            c.abs() <= MAX_CHANGE,
        ));
    }
    let l99 = loaded.analysis.latency_us(0.99);
    list.push((
        format!("p99 with telemetry clients {l99} µs <= {MAX_P99_US} µs"),
        l99 <= MAX_P99_US,
    ));
    let passed = list.iter().all(|(_, ok)| *ok);
    (list, passed)
}
