//! The line and who answers on it: what an idle line carries (the doctor
//! listens, sending nothing), then a scan of the ids at the baud asked and,
//! when nobody answers there, at each other baud of SPEC §1 in turn,
//! saying which baud the devices answer at.
//!
//! A scan asks each id for INFO_01 once, and again (twice at most) only
//! when garbled bytes came back, as the daemon's scan does: silence means
//! nobody is there, garbage may be a reply that collided. An id that
//! brings back garbage every time is kept apart: two devices answering at
//! once look exactly like that ([`super::devices`]).

use std::collections::BTreeSet;
use std::io;
use std::time::Duration;

use serde::Serialize;

use crate::protocol::{BaudLevel, InfoBlock};

use super::check::{Check, CheckId};
use super::exchange::{Exchange, Listened};

/// Extra reads of an id that brought back garbage.
const SCAN_RETRIES: u32 = 2;

/// What an idle line carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct IdleFacts {
    pub listened_ms: u64,
    #[serde(flatten)]
    pub heard: Listened,
}

/// One scan of the ids at one baud.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct BaudScan {
    pub baud: u32,
    /// Ids whose INFO_01 came back (late ones included).
    pub answered: Vec<u8>,
    /// Ids that brought back only garbled bytes, every time asked.
    pub garbled: Vec<u8>,
    /// Bytes that formed no frame over the whole scan.
    pub garbage: u64,
}

impl BaudScan {
    /// Something is there: an answer, or garbage where a reply would be.
    pub fn heard_anyone(&self) -> bool {
        !self.answered.is_empty() || !self.garbled.is_empty()
    }
}

/// The line: its idle noise and the scans.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LineFacts {
    pub idle: IdleFacts,
    pub scans: Vec<BaudScan>,
    /// The baud the devices answer at (`None`: nobody, at any).
    pub answering_baud: Option<u32>,
}

impl LineFacts {
    /// The scan at the baud the devices answer at.
    pub fn answering_scan(&self) -> Option<&BaudScan> {
        let baud = self.answering_baud?;
        self.scans.iter().find(|s| s.baud == baud)
    }
}

/// Listens for `span`, sending nothing.
pub(crate) fn listen_idle(ex: &mut Exchange<'_>, span: Duration) -> io::Result<IdleFacts> {
    Ok(IdleFacts {
        listened_ms: span.as_millis() as u64,
        heard: ex.listen(span)?,
    })
}

/// What answer one id gave.
enum Probe {
    Answered,
    Garbled,
    Silent,
}

/// Asks `id` for INFO_01; again only after garbage.
fn probe(ex: &mut Exchange<'_>, id: u8, garbage: &mut u64) -> io::Result<Probe> {
    for _ in 0..=SCAN_RETRIES {
        let heard = ex.ask(id, InfoBlock::Info01)?;
        *garbage += heard.garbage;
        if heard.reply.is_some() {
            return Ok(Probe::Answered);
        }
        if heard.garbage == 0 && heard.crc_errors == 0 {
            return Ok(Probe::Silent);
        }
    }
    Ok(Probe::Garbled)
}

/// Scans `ids` at the port's baud.
pub(crate) fn scan(ex: &mut Exchange<'_>, ids: &[u8]) -> io::Result<BaudScan> {
    ex.take_heard_from();
    let mut s = BaudScan {
        baud: ex.baud(),
        answered: Vec::new(),
        garbled: Vec::new(),
        garbage: 0,
    };
    for &id in ids {
        match probe(ex, id, &mut s.garbage)? {
            Probe::Answered => s.answered.push(id),
            Probe::Garbled => s.garbled.push(id),
            Probe::Silent => {}
        }
    }
    // A reply that came after its window (a slow adapter) is a device too.
    let asked: BTreeSet<u8> = ids.iter().copied().collect();
    let mut answered: BTreeSet<u8> = s.answered.iter().copied().collect();
    answered.extend(ex.take_heard_from().intersection(&asked));
    s.answered = answered.into_iter().collect();
    s.garbled.retain(|id| !s.answered.contains(id));
    Ok(s)
}

/// Scans at `first`, then at each other baud of SPEC §1 until someone is
/// there; the port is left at the baud they answer at (or at `first`).
pub(crate) fn find_baud(
    ex: &mut Exchange<'_>,
    first: u32,
    ids: &[u8],
) -> io::Result<(Vec<BaudScan>, Option<u32>)> {
    let others = BaudLevel::ALL
        .into_iter()
        .map(BaudLevel::baud)
        .filter(|b| *b != first);
    let mut scans = Vec::new();
    for baud in std::iter::once(first).chain(others) {
        if ex.baud() != baud {
            ex.set_baud(baud)?;
        }
        let s = scan(ex, ids)?;
        let found = s.heard_anyone();
        scans.push(s);
        if found {
            return Ok((scans, Some(baud)));
        }
    }
    ex.set_baud(first)?;
    Ok((scans, None))
}

/// What an idle line says of the wiring, or of another host.
pub(crate) fn idle_check(idle: &IdleFacts) -> Check {
    let id = CheckId::IdleLine;
    let (h, ms) = (&idle.heard, idle.listened_ms);
    if h.commands > 0 {
        return Check::fail(
            id,
            format!(
                "another host talks on this line: {} host frames in {ms} ms",
                h.commands
            ),
            "stop the other program or controller on this bus (the vendor tool, a hand's own \
             main controller): one host per bus",
        );
    }
    if h.garbage > 0 {
        return Check::warn(
            id,
            format!(
                "{} bytes of noise in {ms} ms on a line nobody was asked to talk on",
                h.garbage
            ),
            "terminate the line (120 Ω across A and B at both ends), bias it (often a jumper on \
             the adapter), share ground between the adapter and the modules, keep the pair \
             twisted and away from the motor leads",
        );
    }
    if h.replies > 0 {
        return Check::ok(
            id,
            format!(
                "{} device frames in {ms} ms (power-up announcements), no noise",
                h.replies
            ),
        );
    }
    Check::ok(id, format!("silent for {ms} ms"))
}

/// The baud the devices answer at, against the one asked.
pub(crate) fn baud_check(asked: u32, explicit: bool, answering: Option<u32>) -> Check {
    let id = CheckId::Baud;
    match answering {
        Some(b) if b == asked => Check::ok(id, format!("devices answer at {b}")),
        Some(b) if !explicit => Check::ok(
            id,
            format!("devices answer at {b} (nothing answered at the factory {asked})"),
        ),
        Some(b) => Check::fail(
            id,
            format!("nothing answered at {asked}; the devices answer at {b}"),
            format!(
                "use {b}: `--bus PATH@{b}`, or `baud = {b}` in the config (jointd can move every \
                 device to another baud later: `PUT /api/v1/buses/{{bus}}/baud`)"
            ),
        ),
        None => Check::skipped(id, "no device answered at any baud (see devices)"),
    }
}

/// Whether anyone answered at all.
pub(crate) fn devices_check(line: &LineFacts, ids: &[u8]) -> Check {
    let id = CheckId::Devices;
    let Some(scan) = line.answering_scan() else {
        let bauds: Vec<String> = line.scans.iter().map(|s| s.baud.to_string()).collect();
        return Check::fail(
            id,
            format!(
                "no device answered, ids {} at {}",
                id_list(ids),
                bauds.join(", ")
            ),
            "check in turn: the modules' supply (12 V), A and B not swapped (swap them and run \
             again: a swapped pair is silent), ground shared with the adapter, the id range \
             (`--ids 1-159`), on a board UART its RS-485 direction (see the adapter)",
        );
    };
    let mut found = format!("ids {} answer at {}", id_list(&scan.answered), scan.baud);
    if !scan.garbled.is_empty() {
        found.push_str(&format!(
            "; ids {} bring back garbled bytes",
            id_list(&scan.garbled)
        ));
    }
    Check::ok(id, found)
}

/// `1-4, 7, 9-10`.
pub(crate) fn id_list(ids: &[u8]) -> String {
    let mut sorted: Vec<u8> = ids.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i;
        while j + 1 < sorted.len() && sorted[j + 1] == sorted[j] + 1 {
            j += 1;
        }
        parts.push(if j > i {
            format!("{}-{}", sorted[i], sorted[j])
        } else {
            sorted[i].to_string()
        });
        i = j + 1;
    }
    if parts.is_empty() {
        return "none".into();
    }
    parts.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::check::Verdict;

    #[test]
    fn id_lists_read_as_people_write_them() {
        assert_eq!(id_list(&[7, 1, 2, 3, 4, 9, 10]), "1-4, 7, 9-10");
        assert_eq!(id_list(&[5]), "5");
        assert_eq!(id_list(&[]), "none");
    }

    #[test]
    fn a_baud_found_elsewhere_fails_only_when_it_was_asked_for() {
        let asked = baud_check(230_400, true, Some(500_000));
        assert_eq!(asked.verdict, Verdict::Fail);
        assert!(asked.fix.unwrap_or_default().contains("@500000"));
        assert_eq!(
            baud_check(230_400, false, Some(500_000)).verdict,
            Verdict::Ok
        );
        assert_eq!(
            baud_check(500_000, true, Some(500_000)).verdict,
            Verdict::Ok
        );
        assert_eq!(baud_check(500_000, true, None).verdict, Verdict::Skipped);
    }

    #[test]
    fn an_idle_line_with_noise_or_another_host_says_so() {
        let idle = |heard: Listened| IdleFacts {
            listened_ms: 500,
            heard,
        };
        let noise = Listened {
            bytes: 7,
            garbage: 7,
            ..Listened::default()
        };
        assert_eq!(idle_check(&idle(noise)).verdict, Verdict::Warn);
        let host = Listened {
            bytes: 20,
            commands: 1,
            ..Listened::default()
        };
        assert_eq!(idle_check(&idle(host)).verdict, Verdict::Fail);
        assert_eq!(idle_check(&idle(Listened::default())).verdict, Verdict::Ok);
    }
}
