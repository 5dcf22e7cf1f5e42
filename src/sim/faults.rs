//! Faults that can be switched on and off while the simulator runs, and the
//! line-level ones' state (corruption, dropped replies, extra turnaround).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::protocol::FrameBytes;

use super::rng::Rng;

/// A fault to inject (or clear) at run time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// Each byte on the line (either direction) is garbled with this probability.
    CorruptRate(f64),
    /// Replies of one device (or all) vanish with this probability.
    DropReplies {
        dev_id: Option<u8>,
        rate: f64,
    },
    /// Added to every device's turnaround.
    ExtraTurnaround(Duration),
    /// The device's receiver misses the next `count` control frames meant
    /// for it (its id or `0xFF`), as noise on its stub would make it; other
    /// frames still reach it. For proving that an e-stop checks its work.
    MissControl {
        dev_id: u8,
        count: u32,
    },
    /// An obstacle at `at_deg` (reported °), or right where the joint is now.
    Stall {
        dev_id: u8,
        at_deg: Option<f64>,
    },
    /// An elastic object at `at_deg` (reported °) pushing back `nm_per_deg`
    /// N·m per degree the joint presses in (replaces any earlier one).
    Object {
        dev_id: u8,
        at_deg: f64,
        nm_per_deg: f64,
    },
    /// The object pulled away from the joint.
    RemoveObject {
        dev_id: u8,
    },
    /// Power off and on: RAM from flash, INFO_01 re-announced.
    PowerCycle {
        dev_id: u8,
    },
    UnderVoltage {
        dev_id: u8,
        on: bool,
    },
    /// The whole bus unplugged: the host's port hangs up.
    Unplug,
    /// Plugged back (a pty gets a new /dev/pts node behind the same link).
    Replug,
    /// Host writes reach the USB adapter late by a random delay of this
    /// distribution (`None`: on time). Only behind an adapter model.
    WriteDelay(Option<super::write_delay::WriteDelay>),
    /// The adapter echoes (`true`) every host frame back to the host, as
    /// it was on the wire, or stops echoing.
    Echo(bool),
    /// The adapter's driver count (`TIOCOUTQ`) never falls (`true`), or
    /// counts again. Only behind an adapter model.
    StuckCount(bool),
    /// Noise on the line (a motor lead beside an unshielded pair, a
    /// missing termination): a frame's worth of random bytes reaches the
    /// host every period, whether or not anyone was asked; `None` stops it.
    Noise(Option<Duration>),
    /// Every fault off, obstacles and objects removed, voltage restored, line plugged,
    /// writes on time, no echo, a count that falls.
    ClearAll,
}

/// Line-level fault settings.
#[derive(Debug, Clone, Default)]
pub(crate) struct LineFaults {
    /// [`Fault::Noise`]: its period and when its next burst is due.
    pub noise: Option<(Duration, Instant)>,
    pub corrupt_rate: f64,
    /// Drop rate per device id; `None` is every device.
    pub drop_rates: BTreeMap<Option<u8>, f64>,
    pub extra_turnaround: Duration,
    /// Control frames each device is still to miss.
    pub miss_control: BTreeMap<u8, u32>,
}

impl LineFaults {
    pub(crate) fn set_drop(&mut self, dev_id: Option<u8>, rate: f64) {
        if rate > 0.0 {
            self.drop_rates.insert(dev_id, rate.min(1.0));
        } else {
            self.drop_rates.remove(&dev_id);
        }
    }

    /// Whether device `dev_id` misses this control frame (counting it down).
    pub(crate) fn misses_control(&mut self, dev_id: u8) -> bool {
        match self.miss_control.get_mut(&dev_id) {
            Some(left) if *left > 0 => {
                *left -= 1;
                true
            }
            _ => false,
        }
    }

    /// Whether this device's reply is swallowed this time.
    pub(crate) fn drops(&self, dev_id: u8, rng: &mut Rng) -> bool {
        let all = self.drop_rates.get(&None).copied().unwrap_or(0.0);
        let one = self.drop_rates.get(&Some(dev_id)).copied().unwrap_or(0.0);
        rng.chance(all.max(one))
    }

    /// Garbles bytes at the corruption rate; true if any byte changed.
    pub(crate) fn corrupt(&self, bytes: &mut FrameBytes, rng: &mut Rng) -> bool {
        let mut hit = false;
        for b in bytes.iter_mut() {
            if rng.chance(self.corrupt_rate) {
                // Flip at least one bit so the byte really changes.
                *b ^= (rng.next_u64() as u8) | 1;
                hit = true;
            }
        }
        hit
    }
}

/// What two devices talking at once leave on the line: each bit is pulled
/// low by whichever driver sends a 0 (open-collector reading), and a frame
/// that happens to survive that is garbled in its CRC so it never decodes.
pub(crate) fn collide(a: &FrameBytes, b: &FrameBytes) -> FrameBytes {
    let mut out = [0u8; 20];
    for (o, (x, y)) in out.iter_mut().zip(a.iter().zip(b)) {
        *o = x & y;
    }
    if out == *a || out == *b {
        garble_crc(&mut out);
    }
    out
}

/// What another driver puts on the line during a collision: random bits.
pub(crate) fn noise_frame(rng: &mut Rng) -> FrameBytes {
    let mut out = [0u8; 20];
    for chunk in out.chunks_mut(8) {
        let n = chunk.len();
        chunk.copy_from_slice(&rng.next_u64().to_le_bytes()[..n]);
    }
    out
}

/// The bit pattern a UART at another baud makes of a frame: framing errors
/// and wrong bits. Modelled as the high nibbles stuck (a slower receiver
/// samples the tail of each byte as stop-bit marks), which never decodes.
pub(crate) fn misframed(bytes: &FrameBytes) -> FrameBytes {
    collide(bytes, &[MISFRAMED_MASK; 20])
}

const MISFRAMED_MASK: u8 = 0xF0;

/// Offset of the CRC of a standard frame, the bytes both layouts' CRCs touch.
const CRC_AT: usize = 16;
const CRC_GARBLE: u8 = 0x5A;

/// Makes a frame fail its CRC check (both layouts).
pub(crate) fn garble_crc(bytes: &mut FrameBytes) {
    bytes[CRC_AT] ^= CRC_GARBLE;
    bytes[CRC_AT + 1] ^= CRC_GARBLE;
    bytes[CRC_AT + 2] ^= CRC_GARBLE;
    bytes[CRC_AT + 3] ^= CRC_GARBLE;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Command, Config, Frame, InfoBlock};

    #[test]
    fn identical_frames_colliding_still_fail_crc() {
        let f = Command::Config(Config::read(1, InfoBlock::Info01)).encode();
        assert!(Frame::decode(&collide(&f, &f)).is_err());
    }

    #[test]
    fn misframed_and_noisy_frames_never_decode() {
        let f = Command::Config(Config::read(1, InfoBlock::Info01)).encode();
        assert!(Frame::decode(&misframed(&f)).is_err());
        let mut rng = Rng::new(5);
        assert_ne!(noise_frame(&mut rng), noise_frame(&mut rng));
    }

    #[test]
    fn corruption_at_rate_one_changes_every_byte() {
        let mut rng = Rng::new(3);
        let faults = LineFaults {
            corrupt_rate: 1.0,
            ..Default::default()
        };
        let orig = [0x55u8; 20];
        let mut b = orig;
        assert!(faults.corrupt(&mut b, &mut rng));
        assert!(b.iter().zip(orig.iter()).all(|(x, y)| x != y));
    }

    #[test]
    fn a_device_misses_exactly_the_control_frames_asked() {
        let mut f = LineFaults::default();
        f.miss_control.insert(4, 2);
        assert!(f.misses_control(4));
        assert!(!f.misses_control(5));
        assert!(f.misses_control(4));
        assert!(!f.misses_control(4), "only two");
    }

    #[test]
    fn drop_rate_per_device_or_all() {
        let mut rng = Rng::new(9);
        let mut f = LineFaults::default();
        f.set_drop(Some(2), 1.0);
        assert!(f.drops(2, &mut rng));
        assert!(!f.drops(3, &mut rng));
        f.set_drop(None, 1.0);
        assert!(f.drops(3, &mut rng));
        f.set_drop(None, 0.0);
        assert!(!f.drops(3, &mut rng));
    }
}
