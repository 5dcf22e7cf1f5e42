//! Prometheus' text format: families in order of first use, each with one
//! `HELP` and one `TYPE` line and its samples together; label values escaped.

use std::fmt::Write as _;

use crate::histogram::Histogram;

/// Builds the exposition: families in order of first use, each with one
/// `HELP` and one `TYPE` line and its samples together.
#[derive(Default)]
pub(super) struct Exposition {
    families: Vec<Family>,
}

struct Family {
    name: String,
    kind: &'static str,
    help: String,
    lines: Vec<String>,
}

impl Exposition {
    pub(super) fn family(
        &mut self,
        name: &str,
        kind: &'static str,
        help: &str,
    ) -> &mut Vec<String> {
        let i = match self.families.iter().position(|f| f.name == name) {
            Some(i) => i,
            None => {
                self.families.push(Family {
                    name: name.to_owned(),
                    kind,
                    help: help.to_owned(),
                    lines: Vec::new(),
                });
                self.families.len() - 1
            }
        };
        &mut self.families[i].lines
    }

    fn sample(&mut self, name: &str, kind: &'static str, help: &str, labels: &str, value: f64) {
        let line = if labels.is_empty() {
            format!("{name} {value}")
        } else {
            format!("{name}{{{labels}}} {value}")
        };
        self.family(name, kind, help).push(line);
    }

    pub(super) fn gauge(&mut self, name: &str, help: &str, labels: &str, value: f64) {
        self.sample(name, "gauge", help, labels, value);
    }

    pub(super) fn counter(&mut self, name: &str, help: &str, labels: &str, value: f64) {
        self.sample(name, "counter", help, labels, value);
    }

    pub(super) fn histogram(&mut self, name: &str, help: &str, labels: &str, h: &Histogram) {
        let sep = if labels.is_empty() { "" } else { "," };
        let lines = self.family(name, "histogram", help);
        for (le, n) in h.cumulative() {
            lines.push(format!("{name}_bucket{{{labels}{sep}le=\"{le}\"}} {n}"));
        }
        lines.push(format!(
            "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {}",
            h.count()
        ));
        let braces = |l: &str| {
            if l.is_empty() {
                String::new()
            } else {
                format!("{{{l}}}")
            }
        };
        lines.push(format!("{name}_sum{} {}", braces(labels), h.sum_seconds()));
        lines.push(format!("{name}_count{} {}", braces(labels), h.count()));
    }

    pub(super) fn render(&self) -> String {
        let mut out = String::new();
        for f in &self.families {
            let _ = writeln!(out, "# HELP {} {}", f.name, f.help);
            let _ = writeln!(out, "# TYPE {} {}", f.name, f.kind);
            for line in &f.lines {
                let _ = writeln!(out, "{line}");
            }
        }
        out
    }
}

/// A label value with `\`, `"` and newlines escaped.
pub(super) fn label(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_histogram_renders_cumulative_buckets_sum_and_count() {
        let mut h = Histogram::default();
        h.observe(std::time::Duration::from_micros(300));
        h.observe(std::time::Duration::from_millis(2));
        let mut m = Exposition::default();
        m.histogram("x_seconds", "X.", "bus=\"a\"", &h);
        let text = m.render();
        assert!(
            text.contains("# HELP x_seconds X.\n# TYPE x_seconds histogram\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"0.0005\"} 1\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"0.0025\"} 2\n"),
            "{text}"
        );
        assert!(
            text.contains("x_seconds_bucket{bus=\"a\",le=\"+Inf\"} 2\n"),
            "{text}"
        );
        assert!(text.contains("x_seconds_count{bus=\"a\"} 2\n"), "{text}");
    }
}
