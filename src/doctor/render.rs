//! The report as a person reads it: each check on a line with its
//! verdict, the fix under it, a table of the devices, the proposed
//! `[[bus]]` and the rates to expect, and the verdict at the end.

use std::fmt::Write;

use super::check::{human_us, Check, Verdict};
use super::devices::DeviceFacts;
use super::propose::Proposal;
use super::report::Report;

/// Width of a check's title column.
const TITLE: usize = 32;
/// Where a check's text starts: `  [warn] ` and the title.
const INDENT: usize = 9 + TITLE + 1;

/// The whole report, for a terminal.
pub fn text(r: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "jointd doctor {} at {} baud (jointd {})",
        r.path.display(),
        r.baud_asked,
        r.jointd
    );
    let mut section = "";
    for c in &r.checks {
        if c.id.section() != section {
            section = c.id.section();
            let _ = writeln!(out, "\n{section}");
        }
        check(&mut out, c);
    }
    if !r.devices.is_empty() {
        devices(&mut out, &r.devices);
    }
    if let Some(p) = &r.proposal {
        proposal(&mut out, p);
    }
    let _ = writeln!(
        out,
        "\nverdict: {} ({} failed, {} warnings, {} ok, {} skipped)",
        r.verdict.as_str(),
        r.count(Verdict::Fail),
        r.count(Verdict::Warn),
        r.count(Verdict::Ok),
        r.count(Verdict::Skipped),
    );
    if r.held {
        let _ = writeln!(
            out,
            "the port is held by another process: nothing else was examined"
        );
    }
    out
}

fn check(out: &mut String, c: &Check) {
    let _ = writeln!(
        out,
        "  [{:<4}] {:<width$} {}",
        c.verdict.as_str(),
        c.id.title(),
        c.found,
        width = TITLE
    );
    if let Some(fix) = &c.fix {
        let pad = " ".repeat(INDENT);
        let mut lines = fix.lines();
        if let Some(first) = lines.next() {
            let _ = writeln!(out, "{}fix: {first}", " ".repeat(INDENT - 5));
        }
        for line in lines {
            let _ = writeln!(out, "{pad}{line}");
        }
    }
}

fn devices(out: &mut String, devices: &[DeviceFacts]) {
    let _ = writeln!(out);
    row(
        out,
        [
            "id", "firmware", "rev", "state", "fault", "reads", "ok", "timeouts", "garbled", "crc",
        ],
        "round trip p50 / p99",
    );
    for d in devices {
        let trip = d.round_trip.map_or("-".to_string(), |s| {
            format!("{} / {}", human_us(s.p50_us), human_us(s.p99_us))
        });
        let (id, reads, ok) = (
            d.id.to_string(),
            d.asked.to_string(),
            d.answered.to_string(),
        );
        let (timeouts, garbled) = (d.timeouts.to_string(), d.garbled.to_string());
        let crc = d.crc_errors.to_string();
        let text = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
        let (firmware, rev) = (text(&d.firmware), text(&d.revision));
        let (state, fault) = (text(&d.state), text(&d.fault));
        row(
            out,
            [
                id.as_str(),
                firmware.as_str(),
                rev.as_str(),
                state.as_str(),
                fault.as_str(),
                reads.as_str(),
                ok.as_str(),
                timeouts.as_str(),
                garbled.as_str(),
                crc.as_str(),
            ],
            &trip,
        );
    }
}

/// One line of the devices' table: ten columns, then the round trip.
fn row(out: &mut String, c: [&str; 10], last: &str) {
    let _ = writeln!(
        out,
        "  {:>3} {:<9} {:<6} {:<11} {:<19} {:>5} {:>3} {:>8} {:>8} {:>4}  {last}",
        c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9]
    );
}

fn proposal(out: &mut String, p: &Proposal) {
    let _ = writeln!(out, "\nproposed bus config (a [[bus]] of jointd.toml):\n");
    for line in p.toml.lines() {
        let _ = writeln!(out, "    {line}");
    }
    for note in &p.notes {
        let _ = writeln!(out, "  note: {note}");
    }
    let r = &p.rates;
    let _ = writeln!(
        out,
        "\nexpected on it: {:.0} control updates/s and {:.1} telemetry samples/s per joint with \
         every target streaming, {:.1} samples/s per joint polling alone; the wire carries {:.0} \
         frames/s ({}).",
        r.control_hz, r.telemetry_hz, r.telemetry_idle_hz, r.wire_frames_per_s, r.bound
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::access::AccessFacts;
    use crate::doctor::check::CheckId;
    use crate::doctor::port::PortFacts;

    #[test]
    fn each_check_has_its_line_and_its_fix_under_it() {
        let port = PortFacts::unknown("/dev/ttyUSB0");
        let mut r = Report::new(500_000, port, AccessFacts::default());
        r.push(Check::ok(CheckId::PortKind, "a pty"));
        r.push(Check::warn(CheckId::Echo, "echoes", "line one\nline two"));
        let t = text(&r);
        assert!(t.contains("\nport\n  [ok  ] what the port is"), "{t}");
        assert!(t.contains("[warn] echo of its own bytes"), "{t}");
        assert!(t.contains("fix: line one\n"), "{t}");
        assert!(
            t.contains(&format!("\n{}line two", " ".repeat(INDENT))),
            "{t}"
        );
        assert!(
            t.contains("verdict: warn (0 failed, 1 warnings, 1 ok, 0 skipped)"),
            "{t}"
        );
    }
}
