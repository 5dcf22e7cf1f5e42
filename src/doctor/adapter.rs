//! The adapter between the host and the line, measured on this one: its
//! latency timer (as the system had it, as jointd's open left it, and
//! whether this user may set it), RS-485 direction on a board UART,
//! whether its driver's output count (`TIOCOUTQ`) can be read and when it
//! falls after a write (what confirmed writes rest on,
//! [`crate::bus::usb::confirm`]), and whether it echoes its own bytes.
//!
//! The writes measured are INFO_01 reads of an id nobody answered
//! ([`super::exchange`]): each is followed by its whole reply window, so
//! nothing is on the wire when the next goes.

use std::io;
use std::path::Path;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::bus::usb::confirm::{MAX_UNTAKEN, MAX_WAITED};
use crate::bus::usb::frame_clock::{FramePhase, PHASE_SAMPLES};
use crate::protocol::InfoBlock;
use crate::transport::adapter::{AdapterInfo, AdapterModel};
use crate::transport::PortNote;

use super::check::{human_us, Check, CheckId, Spread};
use super::exchange::{CountWatch, Exchange, Tally};
use super::port::PortKind;

/// A count that never fell this many times is not watched further: each
/// costs [`MAX_WAITED`].
const MAX_NEVER_FELL: u32 = 3;
/// The USB frame assumed when the port shows no USB adapter but has a
/// count (a simulated adapter on a pty): full speed.
const ASSUMED_FRAME: Duration = Duration::from_millis(1);

/// What the adapter is and how it behaved.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AdapterFacts {
    /// The model jointd plans for, from sysfs once the port is open (`ftdi:1`).
    pub model: String,
    /// How it was found: `usb 0403:6001 (ftdi_sio)`.
    pub found_by: String,
    pub usb: bool,
    /// What opening the port noted (RS-485 mode, low latency).
    pub notes: Vec<String>,
    pub count: CountFacts,
    /// Frames written and what came back besides replies (echoes included).
    pub tally: Tally,
}

/// The driver's output count, write by write.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CountFacts {
    pub readable: bool,
    pub writes: u32,
    /// Fell to 0 after the write.
    pub fell: u32,
    /// Of those, later than the daemon waits before it doubts a write ([`MAX_UNTAKEN`]).
    pub late: u32,
    /// Read 0 at the first look: it does not follow the transfer.
    pub zero_at_once: u32,
    /// Still up [`MAX_WAITED`] after the write.
    pub never_fell: u32,
    /// From the write to the fall.
    pub fall: Option<Spread>,
    /// The falls land on one phase of the USB frame, as a transfer's
    /// completion does (`None`: too few to tell).
    pub on_frame_boundary: Option<bool>,
}

/// The adapter found when the port opened, and the notes of the open.
pub(crate) fn facts_of(notes: &[PortNote]) -> (AdapterInfo, Vec<String>) {
    let mut info = AdapterInfo {
        model: AdapterModel::Native,
        found_by: "not reported by the port".into(),
        tty_without_usb: false,
        usb: false,
    };
    let mut text = Vec::new();
    for note in notes {
        match note {
            PortNote::Adapter(a) => info = a.clone(),
            PortNote::Rs485(t) => text.push(t.clone()),
            PortNote::IoctlUnsupported { what, error } => text.push(format!("{what}: {error}")),
        }
    }
    (info, text)
}

/// Watches the count after each of `writes` reads of `id`, which nobody answers.
pub(crate) fn measure_count(ex: &mut Exchange<'_>, id: u8, writes: u32) -> io::Result<CountFacts> {
    let mut facts = CountFacts {
        readable: true,
        ..CountFacts::default()
    };
    let (mut falls, mut at) = (Vec::new(), Vec::new());
    for _ in 0..writes {
        let sent = ex.send(id, InfoBlock::Info01)?;
        let watch = ex.watch_count(&sent);
        ex.hear(&sent)?;
        facts.writes += 1;
        match watch {
            CountWatch::Unreadable => {
                facts.readable = false;
                return Ok(facts);
            }
            CountWatch::ZeroAtOnce => facts.zero_at_once += 1,
            CountWatch::NeverFell => facts.never_fell += 1,
            CountWatch::Fell { after, at: when } => {
                facts.fell += 1;
                facts.late += u32::from(after > MAX_UNTAKEN);
                falls.push(after);
                at.push(when);
            }
        }
        if facts.never_fell >= MAX_NEVER_FELL {
            break;
        }
    }
    facts.fall = Spread::of(&falls);
    let period = ex.adapter().usb_frame().unwrap_or(ASSUMED_FRAME);
    facts.on_frame_boundary = on_frame_boundary(&at, period);
    Ok(facts)
}

/// Whether confirmed writes may rely on the count: it falls after a
/// write and not at once (a port without a count has nothing to rely on,
/// and nothing to turn off; a count not watched, `--writes 0`, is not
/// doubted either).
pub(crate) fn believable(c: &CountFacts) -> bool {
    !c.readable || c.writes == 0 || (c.fell > 0 && c.zero_at_once < c.writes)
}

/// Whether the falls cluster on one phase of a `period` grid, as the
/// daemon's frame clock would learn it from reply arrivals (`None` with
/// fewer falls than it learns from).
pub(crate) fn on_frame_boundary(falls: &[Instant], period: Duration) -> Option<bool> {
    if falls.len() < PHASE_SAMPLES {
        return None;
    }
    let mut phase = FramePhase::new(period);
    falls.iter().for_each(|t| phase.arrival(*t));
    Some(phase.known())
}

/// The latency timer: before and after jointd's open, and its fix.
pub(crate) fn latency_check(
    model: AdapterModel,
    before_ms: Option<u32>,
    timer_file: Option<&Path>,
    writable: bool,
) -> Check {
    let id = CheckId::LatencyTimer;
    let Some(timer) = model.latency_timer() else {
        return Check::skipped(
            id,
            match model {
                AdapterModel::Native => "no USB adapter: no timer holds the replies",
                _ => "no latency timer on this chip: replies reach the host at the next USB frame",
            },
        );
    };
    let ms = timer.as_millis();
    let was = before_ms.map_or(String::new(), |b| format!(" (it was {b} ms before)"));
    if ms <= 1 {
        return Check::ok(
            id,
            format!("{ms} ms once jointd opened the port, which asks for low latency{was}"),
        );
    }
    let file = timer_file.map_or(
        "/sys/bus/usb-serial/devices/ttyUSB0/latency_timer".into(),
        |f| f.display().to_string(),
    );
    let now = if writable {
        format!("this user may set it now: `echo 1 > {file}`")
    } else {
        format!("`echo 1 | sudo tee {file}`")
    };
    Check::warn(
        id,
        format!(
            "{ms} ms after jointd's open{was}: each reply waits up to {ms} ms in the chip. \
             jointd still reaches the adapter's bound (polls are written ahead), but every \
             sample is {ms} ms older and a one-shot request takes {} ms",
            ms + 1
        ),
        format!(
            "{now}; for good, the rule in deploy/99-jointd.rules: \
             ACTION==\"add\", SUBSYSTEM==\"usb-serial\", DRIVERS==\"ftdi_sio\", ATTR{{latency_timer}}=\"1\""
        ),
    )
}

/// RS-485 direction: a board UART needs the driver to switch it.
pub(crate) fn rs485_check(kind: &PortKind, notes: &[String]) -> Check {
    let id = CheckId::Rs485;
    if !matches!(kind, PortKind::Uart { .. }) {
        return Check::skipped(
            id,
            "a USB adapter switches direction itself; a pty has no line",
        );
    }
    match notes.iter().find(|n| n.contains("RS-485")) {
        Some(n) if n.contains("TIOCSRS485") => Check::warn(
            id,
            format!("the UART's driver has no RS-485 mode ({n})"),
            "use a transceiver that switches direction by itself, or give the driver the \
             direction pin (device tree: `linux,rs485-enabled-at-boot-time`, `rts-gpios`)",
        ),
        Some(n) => Check::ok(id, n.clone()),
        None => Check::skipped(id, "RS-485 mode was not asked for"),
    }
}

/// The output count: what confirmed writes can make of it.
pub(crate) fn count_check(c: &CountFacts, usb: bool) -> Check {
    let id = CheckId::OutputCount;
    if !c.readable && !usb {
        return Check::skipped(id, "no USB adapter: a write reaches the line when written");
    }
    if !c.readable {
        return Check::warn(
            id,
            "the driver does not report its output count: writes behind this adapter are \
             blind, and the pipeline learns their lateness from collisions' aftermath",
            "nothing to set (jointd guards blind writes); FTDI, CH340 and CP2102 drivers report it",
        );
    }
    if c.writes == 0 {
        return Check::skipped(id, "no write was watched (`--writes 0`)");
    }
    fall_check(c)
}

/// The count was read over `c.writes` writes: how it fell after them.
fn fall_check(c: &CountFacts) -> Check {
    let id = CheckId::OutputCount;
    let off = "set `timing.usb_confirm = false` for this bus (the proposal below does)";
    let spread = c.fall.as_ref().map_or("-".into(), Spread::describe);
    if c.fell == 0 && c.never_fell > 0 {
        let waited = human_us(MAX_WAITED.as_secs_f64() * 1e6);
        return Check::fail(
            id,
            format!(
                "the count never fell within {waited} of a write ({} of {} writes), though the \
                 bytes went out: confirmed writes would wait {waited} on each, then give up",
                c.never_fell, c.writes
            ),
            off,
        );
    }
    if c.zero_at_once == c.writes {
        return Check::warn(
            id,
            "the count reads 0 at once after every write: it does not follow the USB transfer \
             and cannot confirm a write",
            off,
        );
    }
    if c.never_fell > 0 {
        return Check::warn(
            id,
            format!(
                "the count stayed up {} of {} times (fell {spread} otherwise)",
                c.never_fell, c.writes
            ),
            format!("if jointd logs `USB pipeline backed off` often, {off}"),
        );
    }
    if c.late > 0 {
        return Check::warn(
            id,
            format!(
                "fell {spread} after a write; {} of {} later than {}: some writes reach the \
                 adapter late (confirmed writes make that lost time, never a collision)",
                c.late,
                c.writes,
                human_us(MAX_UNTAKEN.as_secs_f64() * 1e6)
            ),
            "nothing to set; a USB port of its own (no hub shared with a camera) helps",
        );
    }
    let frame = match c.on_frame_boundary {
        Some(true) => ", on a USB frame boundary",
        Some(false) => ", at no fixed phase of the USB frame",
        None => "",
    };
    Check::ok(
        id,
        format!("falls {spread} after a write{frame}: confirmed writes work as jointd assumes"),
    )
}

/// Whether the adapter hands the host back what it sent.
pub(crate) fn echo_check(t: &Tally) -> Check {
    let id = CheckId::Echo;
    if t.writes == 0 {
        return Check::skipped(id, "nothing was written");
    }
    if t.echoes == 0 {
        return Check::ok(id, format!("none of {} frames came back", t.writes));
    }
    let found = if t.echoes * 2 >= t.writes {
        format!(
            "the adapter echoes what it sends: {} of {} frames came back",
            t.echoes, t.writes
        )
    } else {
        format!(
            "{} of {} frames came back: a receiver enabled part of the time, or something repeating them",
            t.echoes, t.writes
        )
    };
    Check::warn(
        id,
        found,
        "jointd skips its own frames (they are not replies), but each costs a read and, behind \
         USB, shares the chip's packets with the replies: turn the echo off if the adapter can \
         (a jumper or switch named ECHO or RE; on a home-made interface tie the transceiver's \
         /RE to DE so its receiver is off while it drives)",
    )
}

#[cfg(test)]
#[path = "adapter_tests.rs"]
mod tests;
