//! Firmware profiles: which protocol revision each simulated module's
//! firmware implements, and every place its behaviour differs. The device
//! asks its [`Profile`]; nothing else in the simulator tests a revision.
//!
//! # What differs
//! | behaviour | V2.0.1 (default) | rev 2.0.8 |
//! |---|---|---|
//! | control frame EN = 0 | no-op | applies the references like SET_REF (SPEC §4.1, errata 10) |
//! | position mode, speed reference 0 | does not move (a limit of 0) | moves at `CONFIG_SPD_LIMIT` (index 30) |
//! | non-zero speed reference | as sent | capped by `CONFIG_SPD_LIMIT` (both modes) |
//! | indices 28, 30, 31 (writes) | unknown: ignored, no reply | stored (RAM, saved by WRITE_FLASH) |
//! | index 32 INFO_07 (read) | unknown: no reply | answers the serial number bytes |
//! | over-temperature threshold | fixed at the factory 90 °C | index 28; the fault clears 10 °C below it |
//! | mode 3 (current) | ignored | drives the q-axis current from `cur_ref` |
//! | UPDATE_ENC_ZERO (index 5) | no reply | RES |
//! | fsm codes | 0, 5, 7, 9 | also 1 init, 2 precharge, 6 start, 8 stop, 10 brake |
//! | err_code | the fault | low nibble active, high nibble latched history |
//! | alignment after the first enable | the configured time | 1× to 5× it, by load |
//! | `0xB155` with its CRC over bytes 0..18 | refused | accepted (both coverages) |
//! | vendor SDK enable-all (standard frame, can_id `0xB1`, `[id, op]`) | ignored | op 1 enables, 0 or 2 disables `id` (`0xFF`: all) |
//! | vendor SDK current broadcast (`55 AF` / `55 B0`) | ignored | ignored (its scale is the SDK's own; no table documents it) |
//! | INFO_06 bytes 2..8 | zero | the simulator's layout (below) |
//!
//! Unchanged in both: config writes to `0xFF` reach every device (SPEC §8
//! lists config writes for `0xFF` without a revision mark; §4.3 marks it rev
//! 2.0.8, so V2.0.1 devices keep what the simulator did before profiles).
//! Reads are never broadcast.
//!
//! # Assumptions (the SPEC is silent; the simulator's choices, not facts)
//! - **Writes with a reply sent to `0xFF`** (WRITE_FLASH, BAUD_RATE, SET_ID,
//!   rev 2.0.8 UPDATE_ENC_ZERO): every device applies the write and answers as
//!   for its own id, so on a bus of more than one device the replies collide
//!   on the half-duplex line and the host gets garbage. SPEC §8 says two
//!   devices that are both addressed both answer and collide; nothing says a
//!   broadcast write suppresses the RES. A host must verify such writes by
//!   read-back, never by the RES.
//! - **State codes**: power-up spends the first half of the boot delay in
//!   init (1), the second half in precharge (2), then ready (0); the device is
//!   deaf during both and announces ready. Enable: align (5, first time only)
//!   → start (6) for [`START_TIME`] → run (7). Disable: stop (8) for
//!   [`STOP_TIME`] → ready, or, if the joint is still turning faster than
//!   [`BRAKE_DONE_DEG_S`], brake (10, the motor brakes the joint to rest)
//!   first. Enable is refused outside ready, as in V2.0.1. References sent
//!   during start are kept.
//! - **Fault history**: the high nibble is the last fault that was active
//!   since power-up, latched when it occurs (so an active stall reads `0x88`);
//!   it survives disable and the fault's recovery and clears only at a power
//!   cycle or reboot.
//! - **Over-temperature** (index 28): the fault engages above the threshold
//!   while running; the active code stays until the winding has cooled to
//!   10 °C below it (disable does not clear it, enable re-faults until then);
//!   when it clears, a device sitting in fault goes back to ready.
//! - **Current mode**: the reference is `cur_ref` of SET_REF / EN = 0
//!   control frames (Q15 of 5.625 A, SPEC §6); the SPEC does not say so, it
//!   is the only current field the protocol has. A free joint turns at the
//!   speed where viscous friction takes what the hold (static) current leaves
//!   of it; against an obstacle the current pushes (stall rules apply). Enable
//!   and the switch into current mode reset the reference to 0 A.
//! - **Alignment load**: unloaded 1× the configured align time; with an
//!   obstacle on the joint 3×; pressed against it 5× (1–5 s at the 1 s default).
//!   Deterministic: no dice.
//! - **Serial number**: a rev 2.0.8 device whose flash holds serial 0 gets
//!   [`default_serial`] (distinct per bus slot, derived from the seed).
//!   INFO_07 carries the serial u16 at bytes 0..2, the rest zero.
//! - **INFO_06 tail** (offsets unpublished): `[2..4]` encoder offset u16 (a
//!   per-device constant from the seed; the simulator has no encoder),
//!   `[4]` DRV_OT °C, `[5..7]` SPD_LIMIT Q15, `[7]` 0.

use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

use crate::protocol::params::{self, index, Revision};
use crate::protocol::CrcCoverage;

use super::error::SimError;

/// Rev 2.0.8 start state (6) between align/ready and run.
pub(crate) const START_TIME: Duration = Duration::from_millis(10);
/// Rev 2.0.8 stop state (8) between a disable and ready.
pub(crate) const STOP_TIME: Duration = Duration::from_millis(10);
/// Rev 2.0.8 brake (10) lasts until the joint is slower than this, output °/s.
pub(crate) const BRAKE_DONE_DEG_S: f64 = 1.0;
/// Over-temperature recovers this far below the threshold (SPEC §4.3, index 28).
pub(crate) const OT_RECOVERY_C: f64 = 10.0;
/// Alignment time factors by load (rev 2.0.8: 1–5 s).
const ALIGN_UNLOADED: u32 = 1;
const ALIGN_OBSTACLE: u32 = 3;
const ALIGN_PRESSED: u32 = 5;

/// What the joint carries when an alignment starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum AlignLoad {
    Free,
    /// An obstacle is on the joint's travel.
    Obstacle,
    /// Pressed against the obstacle.
    Pressed,
}

/// Which firmware each device of a bus runs: one revision for all, or per id.
///
/// Text form (both CLIs): `2.0.1`, `2.0.8`, or `IDS=REV,…` with IDS one id
/// or a range (`1-8=2.0.8,9-16=2.0.1`); ids not named run 2.0.1.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Firmware {
    all: Revision,
    by_id: BTreeMap<u8, Revision>,
}

impl Default for Firmware {
    fn default() -> Self {
        Self::all(Revision::V2_0_1)
    }
}

impl Firmware {
    /// Every device runs `rev`.
    pub fn all(rev: Revision) -> Self {
        Self {
            all: rev,
            by_id: BTreeMap::new(),
        }
    }

    /// Parses the text form; ids are checked against the bus by
    /// [`Firmware::check_ids`] (done by [`super::SimConfig::validate`]).
    pub fn parse(spec: &str) -> Result<Self, SimError> {
        let bad = |why: String| SimError::BadFirmware(format!("`{spec}`: {why}"));
        let text = spec.trim();
        if text.is_empty() {
            return Err(bad("empty: give 2.0.1, 2.0.8 or IDS=REV,…".into()));
        }
        if !text.contains('=') {
            return Revision::parse(text)
                .map(Self::all)
                .map_err(|e| bad(e.to_string()));
        }
        let mut by_id = BTreeMap::new();
        for part in text.split(',').map(str::trim) {
            let Some((ids, rev)) = part.split_once('=') else {
                return Err(bad(format!(
                    "`{part}` is not IDS=REV (e.g. 1-8=2.0.8); a bare revision \
                     cannot be mixed with per-id ones"
                )));
            };
            let rev = Revision::parse(rev).map_err(|e| bad(e.to_string()))?;
            let ids = crate::protocol::ids::parse_id_list(ids).map_err(bad)?;
            for id in ids {
                if by_id.insert(id, rev).is_some_and(|old| old != rev) {
                    return Err(bad(format!("device {id} is given two revisions")));
                }
            }
        }
        Ok(Self {
            all: Revision::V2_0_1,
            by_id,
        })
    }

    /// The revision the device configured with `id` runs.
    pub fn revision_of(&self, id: u8) -> Revision {
        self.by_id.get(&id).copied().unwrap_or(self.all)
    }

    /// Refuses a per-id revision for an id the bus does not have.
    pub fn check_ids(&self, bus: &[u8]) -> Result<(), SimError> {
        match self.by_id.keys().find(|id| !bus.contains(id)) {
            Some(id) => Err(SimError::BadFirmware(format!(
                "`{self}` names device {id}, which is not on the bus"
            ))),
            None => Ok(()),
        }
    }
}

impl fmt::Display for Firmware {
    /// The text form [`Firmware::parse`] reads, consecutive ids of one
    /// revision as a range (`9-16=2.0.8`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.by_id.is_empty() {
            return write!(f, "{}", self.all);
        }
        let mut runs: Vec<(u8, u8, Revision)> = Vec::new();
        for (&id, &rev) in &self.by_id {
            match runs.last_mut() {
                Some((_, last, r)) if *r == rev && u16::from(*last) + 1 == u16::from(id) => {
                    *last = id
                }
                _ => runs.push((id, id, rev)),
            }
        }
        let parts: Vec<String> = runs
            .iter()
            .map(|(a, b, rev)| match a == b {
                true => format!("{a}={rev}"),
                false => format!("{a}-{b}={rev}"),
            })
            .collect();
        f.write_str(&parts.join(","))
    }
}

/// The behaviour switches of one device's firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Profile(Revision);

impl Profile {
    pub(crate) fn new(rev: Revision) -> Self {
        Self(rev)
    }

    pub(crate) fn revision(self) -> Revision {
        self.0
    }

    fn rev208(self) -> bool {
        self.0 >= Revision::V2_0_8
    }

    /// Control EN = 0 applies the references.
    pub(crate) fn en_zero_sets_ref(self) -> bool {
        self.rev208()
    }

    /// Whether the firmware knows a config index (its row's revision); an
    /// index no row names is left to the device's generic handling.
    pub(crate) fn knows_index(self, idx: u8) -> bool {
        params::by_index(idx).map_or(true, |row| row.since <= self.0)
    }

    /// `CONFIG_SPD_LIMIT` caps the speed, and speed 0 in position mode means "at the limit".
    pub(crate) fn uses_speed_limit(self) -> bool {
        self.rev208()
    }

    /// Mode 3 (current) is accepted.
    pub(crate) fn current_mode(self) -> bool {
        self.rev208()
    }

    pub(crate) fn enc_zero_replies(self) -> bool {
        self.rev208()
    }

    /// The device passes through init, precharge, start, stop and brake.
    pub(crate) fn transit_states(self) -> bool {
        self.rev208()
    }

    /// The over-temperature threshold, °C: index 28 under rev 2.0.8, the
    /// factory value otherwise (a V2.0.1 device does not know index 28).
    pub(crate) fn drv_ot_c(self, ram: &super::params::Params) -> f64 {
        if self.rev208() {
            ram.physical(index::DRV_OT)
        } else {
            params::by_index(index::DRV_OT).map_or(f64::INFINITY, |r| r.physical(r.default))
        }
    }

    /// Over-temperature clears on its own below the threshold minus 10 °C.
    pub(crate) fn ot_recovers(self) -> bool {
        self.rev208()
    }

    /// err_code as sent: the active fault, with the history in the high nibble under rev 2.0.8.
    pub(crate) fn err_byte(self, active: u8, history: u8) -> u8 {
        if self.rev208() {
            (history << 4) | (active & 0x0F)
        } else {
            active
        }
    }

    /// Alignment time for a load, from the configured one.
    pub(crate) fn align_time(self, base: Duration, load: AlignLoad) -> Duration {
        if !self.rev208() {
            return base;
        }
        base * match load {
            AlignLoad::Free => ALIGN_UNLOADED,
            AlignLoad::Obstacle => ALIGN_OBSTACLE,
            AlignLoad::Pressed => ALIGN_PRESSED,
        }
    }

    /// Whether a `0xB155` frame with this CRC coverage is obeyed.
    /// The vendor MotorSDK's enable-all frame (can_id 0xB1): the vendor
    /// document prints it as its `0xB155` example (SPEC errata 3) and the
    /// SDK written for current firmware sends it; modelled on rev 2.0.8.
    pub(crate) fn vendor_enable_all(self) -> bool {
        self.0 >= Revision::V2_0_8
    }

    pub(crate) fn accepts_enable_broadcast(self, crc: CrcCoverage) -> bool {
        crc == CrcCoverage::Values || self.rev208()
    }

    /// INFO_06 bytes 2..8 (rev 2.0.8; the layout is the simulator's choice).
    pub(crate) fn info06_tail(
        self,
        data: &mut [u8; 8],
        enc_offset: u16,
        drv_ot: u16,
        spd_limit: u16,
    ) {
        if !self.rev208() {
            return;
        }
        data[2..4].copy_from_slice(&enc_offset.to_le_bytes());
        data[4] = u8::try_from(drv_ot).unwrap_or(u8::MAX);
        data[5..7].copy_from_slice(&spd_limit.to_le_bytes());
    }
}

/// The factory serial number of the device in bus slot `slot`: a base from
/// the seed (high byte) plus the slot, so every device of a bus differs and
/// the same seed gives the same serials.
pub(crate) fn default_serial(seed: u64, slot: usize) -> u16 {
    let base = (fold16(seed) & 0xFF00) | 0x0001;
    base.wrapping_add(u16::try_from(slot).unwrap_or(u16::MAX))
}

/// The per-device encoder offset INFO_06 reports (a constant; no encoder is modelled).
pub(crate) fn encoder_offset(seed: u64, slot: usize) -> u16 {
    fold16(seed.rotate_left(17) ^ (slot as u64).wrapping_mul(0x9E37_79B9)) & 0x3FFF
}

fn fold16(x: u64) -> u16 {
    (x ^ (x >> 16) ^ (x >> 32) ^ (x >> 48)) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_revision_for_all_or_per_id() {
        let all = Firmware::parse("2.0.8").unwrap();
        assert_eq!(all.revision_of(1), Revision::V2_0_8);
        assert_eq!(all.revision_of(159), Revision::V2_0_8);
        let mixed = Firmware::parse("1-8=2.0.8, 9-16=2.0.1").unwrap();
        assert_eq!(mixed.revision_of(8), Revision::V2_0_8);
        assert_eq!(mixed.revision_of(9), Revision::V2_0_1);
        assert_eq!(mixed.revision_of(40), Revision::V2_0_1, "not named: 2.0.1");
        assert_eq!(Firmware::default().revision_of(3), Revision::V2_0_1);
        assert_eq!(mixed.to_string(), "1-8=2.0.8,9-16=2.0.1");
        let again = Firmware::parse(&mixed.to_string()).unwrap();
        assert_eq!(again, mixed);
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        for (bad, says) in [
            ("", "empty"),
            ("2.0.5", "not a protocol revision"),
            ("1-4=3.0", "not a protocol revision"),
            ("1-4=2.0.8,2.0.1", "not IDS=REV"),
            ("0=2.0.8", "not a device id"),
            ("5-2=2.0.8", "backwards"),
            ("1-4=2.0.8,3=2.0.1", "two revisions"),
        ] {
            let err = Firmware::parse(bad).unwrap_err().to_string();
            assert!(err.contains(says), "{bad:?}: {err}");
        }
        let f = Firmware::parse("1-8=2.0.8,20=2.0.1").unwrap();
        let err = f
            .check_ids(&[1, 2, 3, 4, 5, 6, 7, 8])
            .unwrap_err()
            .to_string();
        assert!(err.contains("device 20, which is not on the bus"), "{err}");
        assert!(Firmware::parse("2.0.8").unwrap().check_ids(&[1]).is_ok());
    }

    #[test]
    fn serials_differ_per_slot_and_repeat_per_seed() {
        let serials: Vec<u16> = (0..159).map(|s| default_serial(7, s)).collect();
        let mut unique = serials.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), serials.len());
        assert!(serials.iter().all(|s| *s != 0));
        assert_eq!(default_serial(7, 3), default_serial(7, 3));
    }

    #[test]
    fn the_switches_differ_only_under_rev_2_0_8() {
        let (old, new) = (
            Profile::new(Revision::V2_0_1),
            Profile::new(Revision::V2_0_8),
        );
        assert!(!old.knows_index(index::INFO_07_R) && new.knows_index(index::INFO_07_R));
        assert!(old.knows_index(index::MAX_CUR) && new.knows_index(index::MAX_CUR));
        assert!(!old.accepts_enable_broadcast(CrcCoverage::HeadAndValues));
        assert!(old.accepts_enable_broadcast(CrcCoverage::Values));
        assert!(new.accepts_enable_broadcast(CrcCoverage::HeadAndValues));
        assert_eq!(old.err_byte(8, 9), 8);
        assert_eq!(new.err_byte(0, 9), 0x90);
        let s = Duration::from_secs(1);
        assert_eq!(old.align_time(s, AlignLoad::Pressed), s);
        assert_eq!(new.align_time(s, AlignLoad::Free), s);
        assert_eq!(new.align_time(s, AlignLoad::Pressed), 5 * s);
    }
}
