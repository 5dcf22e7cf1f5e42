//! The doctor's report: every check's verdict with what was found and what
//! to do, the facts each part gathered, and the proposed config.
//! Serialized it is `jointd doctor --json`, for a bug report;
//! [`super::render`] writes it for a person.

use std::path::PathBuf;

use serde::Serialize;

use super::access::AccessFacts;
use super::adapter::AdapterFacts;
use super::check::{Check, CheckId, Verdict};
use super::devices::DeviceFacts;
use super::line::LineFacts;
use super::port::PortFacts;
use super::propose::Proposal;

/// Exit status: every check ok, or warnings only.
pub const EXIT_OK: u8 = 0;
/// Exit status: a check failed.
pub const EXIT_FAILED: u8 = 1;
/// Exit status: another process holds the port; it was left untouched.
pub const EXIT_HELD: u8 = 3;

/// Everything the doctor found on one port.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The jointd that wrote it.
    pub jointd: &'static str,
    pub path: PathBuf,
    /// The baud asked for (or the factory 230400 when none was).
    pub baud_asked: u32,
    /// The worst verdict of the checks (a skipped check counts as ok).
    pub verdict: Verdict,
    /// Another process held the port: nothing past the port was examined.
    pub held: bool,
    pub checks: Vec<Check>,
    pub port: PortFacts,
    pub access: AccessFacts,
    pub adapter: Option<AdapterFacts>,
    pub line: Option<LineFacts>,
    pub devices: Vec<DeviceFacts>,
    pub proposal: Option<Proposal>,
}

impl Report {
    pub fn new(baud_asked: u32, port: PortFacts, access: AccessFacts) -> Self {
        Self {
            jointd: env!("CARGO_PKG_VERSION"),
            path: port.path.clone(),
            baud_asked,
            verdict: Verdict::Ok,
            held: false,
            checks: Vec::new(),
            port,
            access,
            adapter: None,
            line: None,
            devices: Vec::new(),
            proposal: None,
        }
    }

    /// Adds a check in its place (the order of [`CheckId`], whatever the
    /// order they were made in); the report's verdict follows the worst.
    pub fn push(&mut self, check: Check) {
        let counted = match check.verdict {
            Verdict::Skipped => Verdict::Ok,
            v => v,
        };
        self.verdict = self.verdict.max(counted);
        let at = self.checks.partition_point(|c| c.id <= check.id);
        self.checks.insert(at, check);
    }

    /// The check of that name, if it was made.
    pub fn check(&self, id: CheckId) -> Option<&Check> {
        self.checks.iter().find(|c| c.id == id)
    }

    /// The verdict of that check (`None`: not made).
    pub fn verdict_of(&self, id: CheckId) -> Option<Verdict> {
        self.check(id).map(|c| c.verdict)
    }

    /// How many checks came out `verdict`.
    pub fn count(&self, verdict: Verdict) -> usize {
        self.checks.iter().filter(|c| c.verdict == verdict).count()
    }

    /// The process's exit status for this report.
    pub fn exit_code(&self) -> u8 {
        match (self.held, self.verdict) {
            (true, _) => EXIT_HELD,
            (false, Verdict::Fail) => EXIT_FAILED,
            _ => EXIT_OK,
        }
    }

    /// `--json`: the whole report, indented.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn empty() -> Report {
        let port = PortFacts::unknown("/dev/ttyUSB0");
        Report::new(230_400, port, AccessFacts::default())
    }

    #[test]
    fn the_verdict_is_the_worst_check_and_sets_the_exit_status() {
        let mut r = empty();
        r.push(Check::skipped(CheckId::LatencyTimer, "no timer"));
        assert_eq!((r.verdict, r.exit_code()), (Verdict::Ok, EXIT_OK));
        r.push(Check::warn(CheckId::Echo, "echoes", "switch it off"));
        assert_eq!((r.verdict, r.exit_code()), (Verdict::Warn, EXIT_OK));
        r.push(Check::fail(CheckId::Baud, "elsewhere", "use 500000"));
        assert_eq!((r.verdict, r.exit_code()), (Verdict::Fail, EXIT_FAILED));
        r.held = true;
        assert_eq!(r.exit_code(), EXIT_HELD);
        assert_eq!(r.verdict_of(CheckId::Echo), Some(Verdict::Warn));
        assert_eq!(r.count(Verdict::Warn), 1);
    }

    #[test]
    fn the_json_names_each_check_and_its_fix() {
        let mut r = empty();
        r.push(Check::fail(CheckId::DuplicateIds, "ids 2", "part them"));
        let v: serde_json::Value = serde_json::from_str(&r.to_json()).expect("json");
        assert_eq!(v["verdict"], "fail");
        assert_eq!(v["checks"][0]["id"], "duplicate_ids");
        assert_eq!(v["checks"][0]["fix"], "part them");
        assert_eq!(v["port"]["kind"]["kind"], "unknown");
    }
}
