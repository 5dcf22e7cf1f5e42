//! Typed device→host replies (SPEC §5).
//!
//! A [`Reply`] always keeps its 8 raw data bytes; [`Reply::body`] is a typed
//! view of them. An index this codec does not know is kept, not rejected.

use super::command::index;
use super::frame::{Frame, FrameBytes, StandardFrame};
use super::params::{self, ReplyKind};
use super::units::{self, FirmwareVersion};

/// A reply frame: `can_id = (index << 16) | (dev_id << 8)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply {
    pub dev_id: u8,
    pub index: u8,
    pub data: [u8; 8],
}

/// What a reply's data bytes mean, by its index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplyBody {
    Info01(Info01),
    Info02(Info02),
    Info03(Gains),
    Info04(Info04),
    Info05(Info05),
    Info06(Info06),
    /// Serial number bytes (rev 2.0.8): layout unpublished.
    Info07([u8; 8]),
    /// RES of SET_ID (4), UPDATE_ENC_ZERO (5), WRITE_FLASH (13), BAUD_RATE (15):
    /// `code` 1 is success, 0 failure.
    Res {
        index: u8,
        code: u8,
    },
    /// An index with no known layout: only the raw bytes (in [`Reply::data`]).
    Unknown {
        index: u8,
    },
}

/// INFO_01: state and health.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info01 {
    pub fsm: u8,
    pub err_code: u8,
    pub soft_ver: u8,
    /// °C + 50.
    pub temp_raw: u8,
    /// Q7 degrees.
    pub angle: i16,
    /// Q7 volts.
    pub vbus: u16,
}

/// INFO_02: fast telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info02 {
    /// Q15 of 5.625 A.
    pub d_cur: i16,
    pub q_cur: i16,
    /// Q15 of the firmware's base rotor speed.
    pub speed: i16,
    /// Q7 degrees.
    pub angle: i16,
}

/// INFO_03: control gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Gains {
    /// Q12.
    pub pos_kp: u16,
    pub pos_kd: u16,
    pub spd_kp: u16,
    /// Q15 (÷ 32768).
    pub spd_ki: u16,
}

/// INFO_04: smoothing, baud, limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info04 {
    pub lpf_level: u8,
    pub baud_level: u8,
    pub param_ver: u8,
    pub reserved: u8,
    /// Q15 of 5.625 A.
    pub max_current: u16,
    pub protect_limit: u16,
}

/// INFO_05: current protection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info05 {
    pub protect_cur_lv1: u16,
    pub protect_delay_lv1_ms: u16,
    pub recv_cur: u16,
    pub recover_delay_ms: u16,
}

/// INFO_06: burst timing; later firmware adds bytes whose offsets are unpublished.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info06 {
    /// × 25 ms.
    pub cold_dt: u8,
    /// × 25 ms.
    pub plus_t: u8,
    pub extra: [u8; 6],
}

/// RES codes.
pub const RES_SUCCESS: u8 = 1;
pub const RES_FAILURE: u8 = 0;

/// True for an index whose reply is a RES byte (the table's reply kind).
pub fn is_res_index(index: u8) -> bool {
    params::by_index(index).is_some_and(|r| r.reply == ReplyKind::Res)
}

fn le_i16(d: &[u8; 8], at: usize) -> i16 {
    i16::from_le_bytes([d[at], d[at + 1]])
}

fn le_u16(d: &[u8; 8], at: usize) -> u16 {
    u16::from_le_bytes([d[at], d[at + 1]])
}

fn put(d: &mut [u8; 8], at: usize, bytes: [u8; 2]) {
    d[at..at + 2].copy_from_slice(&bytes);
}

impl Reply {
    /// The reply a standard frame carries, if its can_id has a reply's shape
    /// (bytes 0 and 3 zero, byte 1 the device id).
    pub fn from_standard(f: &StandardFrame) -> Option<Reply> {
        let [b0, dev_id, idx, b3] = f.can_id.to_le_bytes();
        (b0 == 0 && b3 == 0).then_some(Reply {
            dev_id,
            index: idx,
            data: f.data,
        })
    }

    /// The reply a device sends with this body.
    pub fn new(dev_id: u8, body: ReplyBody) -> Reply {
        let (idx, data) = body.to_index_data();
        Reply {
            dev_id,
            index: idx,
            data,
        }
    }

    pub fn can_id(&self) -> u32 {
        u32::from_le_bytes([0, self.dev_id, self.index, 0])
    }

    pub fn to_frame(&self) -> Frame {
        Frame::Standard(StandardFrame {
            can_id: self.can_id(),
            data: self.data,
        })
    }

    pub fn encode(&self) -> FrameBytes {
        self.to_frame().encode()
    }

    /// The typed view of the data bytes.
    pub fn body(&self) -> ReplyBody {
        let d = &self.data;
        match self.index {
            index::INFO_01_R => ReplyBody::Info01(Info01::from_bytes(d)),
            index::INFO_02_R => ReplyBody::Info02(Info02::from_bytes(d)),
            index::INFO_03_R => ReplyBody::Info03(Gains::from_bytes(d)),
            index::INFO_04_R => ReplyBody::Info04(Info04::from_bytes(d)),
            index::INFO_05_R => ReplyBody::Info05(Info05::from_bytes(d)),
            index::INFO_06_R => ReplyBody::Info06(Info06::from_bytes(d)),
            index::INFO_07_R => ReplyBody::Info07(*d),
            i if is_res_index(i) => ReplyBody::Res {
                index: i,
                code: d[0],
            },
            i => ReplyBody::Unknown { index: i },
        }
    }
}

impl ReplyBody {
    /// Index and data bytes of this body. `Unknown` carries no bytes of its
    /// own, so it encodes as zeros.
    fn to_index_data(self) -> (u8, [u8; 8]) {
        match self {
            ReplyBody::Info01(i) => (index::INFO_01_R, i.to_bytes()),
            ReplyBody::Info02(i) => (index::INFO_02_R, i.to_bytes()),
            ReplyBody::Info03(g) => (index::INFO_03_R, g.to_bytes()),
            ReplyBody::Info04(i) => (index::INFO_04_R, i.to_bytes()),
            ReplyBody::Info05(i) => (index::INFO_05_R, i.to_bytes()),
            ReplyBody::Info06(i) => (index::INFO_06_R, i.to_bytes()),
            ReplyBody::Info07(d) => (index::INFO_07_R, d),
            ReplyBody::Res { index, code } => (index, [code, 0, 0, 0, 0, 0, 0, 0]),
            ReplyBody::Unknown { index } => (index, [0u8; 8]),
        }
    }
}

impl Info01 {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        Self {
            fsm: d[0],
            err_code: d[1],
            soft_ver: d[2],
            temp_raw: d[3],
            angle: le_i16(d, 4),
            vbus: le_u16(d, 6),
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [
            self.fsm,
            self.err_code,
            self.soft_ver,
            self.temp_raw,
            0,
            0,
            0,
            0,
        ];
        put(&mut d, 4, self.angle.to_le_bytes());
        put(&mut d, 6, self.vbus.to_le_bytes());
        d
    }

    pub fn firmware(&self) -> FirmwareVersion {
        FirmwareVersion(self.soft_ver)
    }

    pub fn temp_c(&self) -> f64 {
        units::temp_c(self.temp_raw)
    }

    pub fn angle_deg(&self) -> f64 {
        units::angle_deg(self.angle)
    }

    pub fn vbus_v(&self) -> f64 {
        units::volts(self.vbus)
    }
}

impl Info02 {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        Self {
            d_cur: le_i16(d, 0),
            q_cur: le_i16(d, 2),
            speed: le_i16(d, 4),
            angle: le_i16(d, 6),
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        put(&mut d, 0, self.d_cur.to_le_bytes());
        put(&mut d, 2, self.q_cur.to_le_bytes());
        put(&mut d, 4, self.speed.to_le_bytes());
        put(&mut d, 6, self.angle.to_le_bytes());
        d
    }

    pub fn angle_deg(&self) -> f64 {
        units::angle_deg(self.angle)
    }

    pub fn speed_rpm(&self, fw: FirmwareVersion) -> f64 {
        units::speed_rpm(self.speed, fw)
    }
}

impl Gains {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        Self {
            pos_kp: le_u16(d, 0),
            pos_kd: le_u16(d, 2),
            spd_kp: le_u16(d, 4),
            spd_ki: le_u16(d, 6),
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        put(&mut d, 0, self.pos_kp.to_le_bytes());
        put(&mut d, 2, self.pos_kd.to_le_bytes());
        put(&mut d, 4, self.spd_kp.to_le_bytes());
        put(&mut d, 6, self.spd_ki.to_le_bytes());
        d
    }
}

impl Info04 {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        Self {
            lpf_level: d[0],
            baud_level: d[1],
            param_ver: d[2],
            reserved: d[3],
            max_current: le_u16(d, 4),
            protect_limit: le_u16(d, 6),
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [
            self.lpf_level,
            self.baud_level,
            self.param_ver,
            self.reserved,
            0,
            0,
            0,
            0,
        ];
        put(&mut d, 4, self.max_current.to_le_bytes());
        put(&mut d, 6, self.protect_limit.to_le_bytes());
        d
    }
}

impl Info05 {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        Self {
            protect_cur_lv1: le_u16(d, 0),
            protect_delay_lv1_ms: le_u16(d, 2),
            recv_cur: le_u16(d, 4),
            recover_delay_ms: le_u16(d, 6),
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        put(&mut d, 0, self.protect_cur_lv1.to_le_bytes());
        put(&mut d, 2, self.protect_delay_lv1_ms.to_le_bytes());
        put(&mut d, 4, self.recv_cur.to_le_bytes());
        put(&mut d, 6, self.recover_delay_ms.to_le_bytes());
        d
    }
}

impl Info06 {
    pub fn from_bytes(d: &[u8; 8]) -> Self {
        let mut extra = [0u8; 6];
        extra.copy_from_slice(&d[2..8]);
        Self {
            cold_dt: d[0],
            plus_t: d[1],
            extra,
        }
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let mut d = [self.cold_dt, self.plus_t, 0, 0, 0, 0, 0, 0];
        d[2..8].copy_from_slice(&self.extra);
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_index_keeps_raw_bytes() {
        let r = Reply {
            dev_id: 3,
            index: 99,
            data: [1, 2, 3, 4, 5, 6, 7, 8],
        };
        assert_eq!(r.body(), ReplyBody::Unknown { index: 99 });
        let f = r.to_frame();
        let Frame::Standard(sf) = f else {
            panic!("reply must be a standard frame")
        };
        assert_eq!(Reply::from_standard(&sf), Some(r));
    }

    #[test]
    fn res_reads_success_byte() {
        let r = Reply {
            dev_id: 10,
            index: 4,
            data: [1, 0, 0, 0, 0, 0, 0, 0],
        };
        assert_eq!(r.body(), ReplyBody::Res { index: 4, code: 1 });
        assert_eq!(Reply::new(10, r.body()), r);
        let r = Reply {
            dev_id: 10,
            index: 13,
            data: [0; 8],
        };
        assert_eq!(
            r.body(),
            ReplyBody::Res {
                index: 13,
                code: RES_FAILURE
            }
        );
    }
}
