//! What every part of the doctor reports in: a check's verdict, what was
//! found and what to do; and the timing spreads the checks are made of.
//! The bottom of the folder: pure, imported by every other file.

use std::time::Duration;

use serde::Serialize;

/// How a check came out, best first: the report's verdict is the worst.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Ok,
    /// Not run here (a pty has no latency timer; no device to ask).
    Skipped,
    /// jointd will run, slower or less safely than it could: the fix is worth it.
    Warn,
    /// jointd will not run as it should until this is fixed.
    Fail,
}

impl Verdict {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Skipped => "skip",
            Self::Warn => "warn",
            Self::Fail => "FAIL",
        }
    }
}

/// Every check the doctor makes, in the order it reports them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CheckId {
    /// What the port is: USB adapter, pty, UART.
    PortKind,
    /// A path that survives a replug (`/dev/serial/by-id/…`).
    StablePath,
    /// This user may open it.
    Permission,
    /// No other process holds it.
    Held,
    /// It opened, raw, at the baud asked.
    Open,
    /// RS-485 direction control on a UART.
    Rs485,
    /// The FTDI latency timer.
    LatencyTimer,
    /// The driver's output count (`TIOCOUTQ`): confirmed writes.
    OutputCount,
    /// The adapter echoes what it sends.
    Echo,
    /// Bytes on a line nobody was asked to talk on.
    IdleLine,
    /// The baud the devices answer at.
    Baud,
    /// Devices answer at all.
    Devices,
    /// Two devices share an id.
    DuplicateIds,
    /// Each device's replies over a burst: CRC errors, timeouts.
    Replies,
    /// A device already faulted or enabled.
    DeviceState,
    /// The bus config jointd would run with.
    Proposal,
}

impl CheckId {
    /// The part of the report it belongs to.
    pub fn section(self) -> &'static str {
        match self {
            Self::PortKind | Self::StablePath | Self::Permission | Self::Held | Self::Open => {
                "port"
            }
            Self::Rs485 | Self::LatencyTimer | Self::OutputCount | Self::Echo => "adapter",
            Self::IdleLine | Self::Baud | Self::Devices => "line",
            Self::DuplicateIds | Self::Replies | Self::DeviceState => "devices",
            Self::Proposal => "jointd",
        }
    }

    /// What a person reads beside the verdict.
    pub fn title(self) -> &'static str {
        match self {
            Self::PortKind => "what the port is",
            Self::StablePath => "stable path",
            Self::Permission => "permission",
            Self::Held => "held by another process",
            Self::Open => "opens raw",
            Self::Rs485 => "RS-485 direction",
            Self::LatencyTimer => "latency timer",
            Self::OutputCount => "output count (confirmed writes)",
            Self::Echo => "echo of its own bytes",
            Self::IdleLine => "idle line",
            Self::Baud => "baud",
            Self::Devices => "devices",
            Self::DuplicateIds => "duplicate ids",
            Self::Replies => "replies",
            Self::DeviceState => "device state",
            Self::Proposal => "proposed config",
        }
    }
}

/// One check's outcome.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Check {
    pub id: CheckId,
    pub verdict: Verdict,
    /// What was seen, in a sentence.
    pub found: String,
    /// What to do about it (nothing when it is fine).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fix: Option<String>,
}

impl Check {
    pub fn ok(id: CheckId, found: impl Into<String>) -> Self {
        Self::new(id, Verdict::Ok, found, None)
    }

    pub fn skipped(id: CheckId, why: impl Into<String>) -> Self {
        Self::new(id, Verdict::Skipped, why, None)
    }

    pub fn warn(id: CheckId, found: impl Into<String>, fix: impl Into<String>) -> Self {
        Self::new(id, Verdict::Warn, found, Some(fix.into()))
    }

    pub fn fail(id: CheckId, found: impl Into<String>, fix: impl Into<String>) -> Self {
        Self::new(id, Verdict::Fail, found, Some(fix.into()))
    }

    fn new(id: CheckId, verdict: Verdict, found: impl Into<String>, fix: Option<String>) -> Self {
        Self {
            id,
            verdict,
            found: found.into(),
            fix,
        }
    }
}

/// A timing distribution, µs: how many samples, and their quantiles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub n: usize,
    pub min_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
}

impl Spread {
    /// The spread of `samples` (`None` without any).
    pub fn of(samples: &[Duration]) -> Option<Self> {
        let mut us: Vec<f64> = samples.iter().map(|d| d.as_nanos() as f64 / 1e3).collect();
        us.sort_by(f64::total_cmp);
        let (first, last) = (*us.first()?, *us.last()?);
        Some(Self {
            n: us.len(),
            min_us: first,
            p50_us: quantile(&us, 0.5),
            p90_us: quantile(&us, 0.9),
            p99_us: quantile(&us, 0.99),
            max_us: last,
        })
    }

    /// `p50 … / p99 … / max …` in µs or ms, as a person reads it.
    pub fn describe(&self) -> String {
        format!(
            "p50 {}, p99 {}, max {} (n = {})",
            human_us(self.p50_us),
            human_us(self.p99_us),
            human_us(self.max_us),
            self.n
        )
    }
}

/// The nearest-rank `p`-quantile of sorted values.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 * p).ceil() as usize).saturating_sub(1);
    sorted.get(i).copied().unwrap_or(0.0)
}

/// `850 µs`, `16.2 ms`.
pub fn human_us(us: f64) -> String {
    if us >= 1000.0 {
        format!("{:.1} ms", us / 1000.0)
    } else {
        format!("{us:.0} µs")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_verdict_is_the_greatest() {
        let worst = [Verdict::Ok, Verdict::Warn, Verdict::Skipped]
            .into_iter()
            .max();
        assert_eq!(worst, Some(Verdict::Warn));
        assert!(Verdict::Fail > Verdict::Warn && Verdict::Skipped > Verdict::Ok);
    }

    #[test]
    fn a_spread_has_nearest_rank_quantiles() {
        let samples: Vec<Duration> = (1..=100).map(Duration::from_micros).collect();
        let s = Spread::of(&samples).expect("samples");
        assert_eq!(
            (s.n, s.min_us, s.p50_us, s.p99_us, s.max_us),
            (100, 1.0, 50.0, 99.0, 100.0)
        );
        assert_eq!(Spread::of(&[]), None);
        assert_eq!(human_us(850.0), "850 µs");
        assert_eq!(human_us(16_200.0), "16.2 ms");
    }

    #[test]
    fn every_check_has_a_section_and_a_title() {
        let c = Check::warn(CheckId::Echo, "echoes", "turn it off");
        assert_eq!(
            (c.id.section(), c.id.title()),
            ("adapter", "echo of its own bytes")
        );
        let json = serde_json::to_value(&c).expect("json");
        assert_eq!(json["id"], "echo");
        assert_eq!(json["verdict"], "warn");
        assert!(
            serde_json::to_value(Check::ok(CheckId::Baud, "fine")).expect("json")["fix"].is_null()
        );
    }
}
