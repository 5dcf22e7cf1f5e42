//! Each device, asked over a short burst: its state, firmware and protocol
//! revision (INFO_01, INFO_04, INFO_07: reads only), then reads alternating
//! INFO_02 and INFO_01 as the daemon's polls do, counting replies, CRC
//! errors, garbled bytes and timeouts, and the round trip of each.
//!
//! Two devices with one id answer every read of it at once: their replies
//! overlap and the host gets garbled bytes, or, when their turnarounds
//! differ by more than a frame, two good replies. An id whose reads come
//! back garbled while the others' come back clean is that, not noise.

use std::io;
use std::time::Duration;

use serde::Serialize;

use crate::protocol::params::Revision;
use crate::protocol::status::{active_fault, fault_history, fault_name, fsm, fsm_name};
use crate::protocol::{BaudLevel, Info01, Info04, InfoBlock, ReplyBody};

use super::check::{Check, CheckId, Spread};
use super::exchange::{Exchange, Heard};
use super::line::{id_list, BaudScan};

/// Every Nth read of the burst is INFO_01, as the daemon's poll plan's default.
const INFO01_EVERY: u32 = 8;
/// A device whose reads fail this often fails the check.
const FAIL_RATE: f64 = 0.2;
/// Another device's garbled share below this is a clean line.
const CLEAN_RATE: f64 = 0.1;

/// One device, as the burst found it.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DeviceFacts {
    pub id: u8,
    /// `1.2.8` (INFO_01 `soft_ver`).
    pub firmware: Option<String>,
    /// `2.0.8` when it answers INFO_07, `2.0.1` when it stays silent.
    pub revision: Option<String>,
    pub state: Option<String>,
    pub enabled: bool,
    /// The active fault, when there is one.
    pub fault: Option<String>,
    /// The latched history (rev 2.0.8), when there is one.
    pub fault_history: Option<String>,
    pub vbus_v: Option<f64>,
    pub temp_c: Option<f64>,
    /// The baud its INFO_04 reports.
    pub baud: Option<u32>,
    pub asked: u32,
    pub answered: u32,
    /// Nothing came back.
    pub timeouts: u32,
    /// Only bytes that formed no frame came back.
    pub garbled: u32,
    /// Two good replies to one read.
    pub double_replies: u32,
    pub crc_errors: u64,
    pub garbage_bytes: u64,
    /// From the write to the reply.
    pub round_trip: Option<Spread>,
    /// On a line without USB: the round trip less the request and the
    /// reply on the wire (the device's turnaround and the host's read lag).
    pub turnaround: Option<Spread>,
}

impl DeviceFacts {
    /// Reads that failed (nothing, or garbage), as a share of those asked.
    pub fn failed_share(&self) -> f64 {
        f64::from(self.timeouts + self.garbled) / f64::from(self.asked.max(1))
    }

    fn count(&mut self, heard: &Heard, trips: &mut Vec<Duration>) {
        self.asked += 1;
        self.crc_errors += heard.crc_errors;
        self.garbage_bytes += heard.garbage;
        self.double_replies += u32::from(heard.replies >= 2);
        match (heard.reply.is_some(), heard.garbage > 0) {
            (true, _) => self.answered += 1,
            (false, true) => self.garbled += 1,
            (false, false) => self.timeouts += 1,
        }
        trips.extend(heard.after);
    }

    fn read_state(&mut self, info: &Info01) {
        self.firmware = Some(info.firmware().dotted());
        self.state = Some(fsm_name(info.fsm).to_string());
        self.enabled = matches!(info.fsm, fsm::ALIGN | fsm::START | fsm::RUN);
        let (now, past) = (active_fault(info.err_code), fault_history(info.err_code));
        self.fault = (now != 0).then(|| fault_name(now).to_string());
        self.fault_history = (past != 0).then(|| fault_name(past).to_string());
        self.vbus_v = Some(info.vbus_v());
        self.temp_c = Some(info.temp_c());
    }
}

/// Asks device `id` who it is, then `burst` reads as the daemon polls.
pub(crate) fn examine(ex: &mut Exchange<'_>, id: u8, burst: u32) -> io::Result<DeviceFacts> {
    let mut d = DeviceFacts {
        id,
        ..DeviceFacts::default()
    };
    let mut trips = Vec::new();
    for block in [InfoBlock::Info01, InfoBlock::Info04] {
        let heard = ex.ask(id, block)?;
        d.count(&heard, &mut trips);
        match heard.reply.map(|r| r.body()) {
            Some(ReplyBody::Info01(info)) => d.read_state(&info),
            Some(ReplyBody::Info04(info)) => d.baud = baud_of(&info),
            _ => {}
        }
    }
    // A V2.0.1 device does not know index 32 and stays silent: not a miss.
    let rev = ex.ask(id, InfoBlock::Info07)?;
    d.revision = Some(revision_name(rev.reply.is_some()).to_string());
    for k in 0..burst {
        let block = if k % INFO01_EVERY == 0 {
            InfoBlock::Info01
        } else {
            InfoBlock::Info02
        };
        let heard = ex.ask(id, block)?;
        d.count(&heard, &mut trips);
    }
    d.round_trip = Spread::of(&trips);
    if !ex.adapter().is_latent() {
        let wire = ex.frame() * 2;
        let turns: Vec<Duration> = trips.iter().map(|t| t.saturating_sub(wire)).collect();
        d.turnaround = Spread::of(&turns);
    }
    Ok(d)
}

/// The protocol revision an answer (or silence) to INFO_07 says a device runs.
fn revision_name(answered_info07: bool) -> &'static str {
    if answered_info07 {
        Revision::V2_0_8.as_str()
    } else {
        Revision::V2_0_1.as_str()
    }
}

fn baud_of(info: &Info04) -> Option<u32> {
    BaudLevel::from_raw(info.baud_level).map(BaudLevel::baud)
}

/// The ids that look like two devices: two replies to a read, or garbage
/// every time while the other devices answer clean.
pub(crate) fn suspect_duplicates(
    devices: &[DeviceFacts],
    scan: &BaudScan,
) -> Vec<(u8, &'static str)> {
    let clean_elsewhere = |id: u8| {
        devices
            .iter()
            .filter(|d| d.id != id)
            .all(|d| f64::from(d.garbled) / f64::from(d.asked.max(1)) < CLEAN_RATE)
    };
    let mut found = Vec::new();
    for d in devices {
        let garbled_mostly = d.garbled * 2 >= d.asked.max(1);
        if d.double_replies > 0 {
            found.push((d.id, "two good replies to one read"));
        } else if (garbled_mostly || scan.garbled.contains(&d.id)) && clean_elsewhere(d.id) {
            found.push((
                d.id,
                "its reads come back garbled while the others' come back clean",
            ));
        }
    }
    found
}

/// Two devices with one id: which, why, and how to part them.
pub(crate) fn duplicate_check(devices: &[DeviceFacts], scan: &BaudScan) -> Check {
    let id = CheckId::DuplicateIds;
    let suspects = suspect_duplicates(devices, scan);
    if suspects.is_empty() {
        return Check::ok(id, "every id answers once");
    }
    let why: Vec<String> = suspects
        .iter()
        .map(|(i, w)| format!("id {i}: {w}"))
        .collect();
    let ids: Vec<u8> = suspects.iter().map(|(i, _)| *i).collect();
    Check::fail(
        id,
        format!(
            "ids {} seem to be on two devices each ({})",
            id_list(&ids),
            why.join("; ")
        ),
        "connect the devices with that id one at a time and give each an id of its own \
         (jointd: `PUT /api/v1/buses/{bus}/devices/{id}/id`, or the vendor tool); ids must be \
         unique on a bus (SPEC §8)",
    )
}

/// CRC errors and timeouts over the burst, the suspected duplicates aside.
pub(crate) fn replies_check(devices: &[DeviceFacts], scan: &BaudScan) -> Check {
    let id = CheckId::Replies;
    let dup: Vec<u8> = suspect_duplicates(devices, scan)
        .iter()
        .map(|(i, _)| *i)
        .collect();
    let judged: Vec<&DeviceFacts> = devices.iter().filter(|d| !dup.contains(&d.id)).collect();
    if judged.is_empty() {
        return Check::skipped(id, "no device to judge (see duplicate ids)");
    }
    let bad: Vec<String> = judged
        .iter()
        .filter(|d| d.timeouts + d.garbled > 0 || d.crc_errors > 0)
        .map(|d| {
            format!(
                "id {}: {} timeouts, {} garbled, {} CRC errors of {} reads",
                d.id, d.timeouts, d.garbled, d.crc_errors, d.asked
            )
        })
        .collect();
    let asked: u32 = judged.iter().map(|d| d.asked).sum();
    if bad.is_empty() {
        return Check::ok(
            id,
            format!("every device answered every read ({asked} reads)"),
        );
    }
    let fix = "garbled replies and CRC errors: termination and biasing (see idle line); \
               timeouts: the modules' supply under load, a loose connector, or a turnaround \
               longer than the reply window (`timing.reply_margin_us`)";
    if judged.iter().any(|d| d.failed_share() > FAIL_RATE) {
        Check::fail(id, bad.join("; "), fix)
    } else {
        Check::warn(id, bad.join("; "), fix)
    }
}

/// A device already faulted, or enabled by someone before jointd.
pub(crate) fn state_check(devices: &[DeviceFacts]) -> Check {
    let id = CheckId::DeviceState;
    let mut notes = Vec::new();
    for d in devices {
        if let Some(f) = &d.fault {
            notes.push(format!("id {} reports {f}", d.id));
        }
        if d.enabled {
            let state = d.state.as_deref().unwrap_or("enabled");
            notes.push(format!("id {} is enabled ({state})", d.id));
        }
    }
    if notes.is_empty() {
        return Check::ok(id, "every device is ready, without a fault");
    }
    Check::warn(
        id,
        notes.join("; "),
        "a fault: read it in the dashboard, a disable clears one whose cause is gone; an \
         enabled joint: jointd disables it at start (`on_start = \"disable\"`) unless told to \
         keep it (`on_start = \"keep\"`)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::check::Verdict;

    fn device(id: u8, asked: u32, garbled: u32) -> DeviceFacts {
        DeviceFacts {
            id,
            asked,
            answered: asked - garbled,
            garbled,
            ..DeviceFacts::default()
        }
    }

    fn scan(garbled: &[u8]) -> BaudScan {
        BaudScan {
            baud: 500_000,
            answered: vec![1, 3],
            garbled: garbled.to_vec(),
            garbage: 0,
        }
    }

    #[test]
    fn an_id_garbled_alone_on_a_clean_line_is_two_devices() {
        let devices = [device(1, 50, 0), device(2, 50, 50), device(3, 50, 1)];
        let check = duplicate_check(&devices, &scan(&[2]));
        assert_eq!(check.verdict, Verdict::Fail);
        assert!(check.found.contains("ids 2 "), "{}", check.found);
        // The others are judged apart from it.
        assert_eq!(replies_check(&devices, &scan(&[2])).verdict, Verdict::Warn);
    }

    #[test]
    fn garbage_everywhere_is_noise_not_duplicates() {
        let devices = [device(1, 50, 30), device(2, 50, 30)];
        assert_eq!(duplicate_check(&devices, &scan(&[])).verdict, Verdict::Ok);
        assert_eq!(replies_check(&devices, &scan(&[])).verdict, Verdict::Fail);
    }

    #[test]
    fn two_good_replies_to_one_read_are_two_devices() {
        let mut d = device(4, 50, 0);
        d.double_replies = 50;
        assert_eq!(suspect_duplicates(&[d], &scan(&[])).len(), 1);
    }

    #[test]
    fn an_enabled_or_faulted_device_is_a_warning() {
        let mut d = device(1, 10, 0);
        d.read_state(&Info01 {
            fsm: fsm::RUN,
            err_code: 0x80,
            soft_ver: 128,
            temp_raw: 80,
            angle: 0,
            vbus: 12 * 128,
        });
        assert!(d.enabled && d.fault.is_none());
        assert_eq!(d.fault_history.as_deref(), Some(fault_name(8)));
        assert_eq!(d.firmware.as_deref(), Some("1.2.8"));
        assert_eq!(state_check(&[d]).verdict, Verdict::Warn);
        assert_eq!(state_check(&[device(2, 10, 0)]).verdict, Verdict::Ok);
    }
}
