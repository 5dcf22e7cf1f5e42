//! Typed host→device commands (SPEC §3.2, §4) and their frames.
//!
//! Every command encodes to exactly one frame and decodes back from it; the
//! raw integers are what the wire carries, [`super::units`] converts them.

use super::error::ProtocolError;
use super::frame::{BroadcastFrame, BroadcastKind, CrcCoverage, Frame, FrameBytes, StandardFrame};
use super::ids::is_address;
use super::params::{self, ParamRow, RawType, Scale};

/// can_id of a jog command.
pub const CAN_ID_JOG: u32 = 0xF0;
/// can_id of a config/read command.
pub const CAN_ID_CONFIG: u32 = 0xA0;
/// The key a WRITE_FLASH must carry.
pub const WRITE_FLASH_KEY: u8 = 0xA5;

/// A host→device command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Control(Control),
    Jog(Jog),
    Config(Config),
    BroadcastPos(BroadcastPos),
    BroadcastSpd(BroadcastSpd),
    /// Unverified layout (SPEC errata 3); offered for completeness, never sent by the daemon.
    BroadcastEnableUnverified(BroadcastEnable),
    /// Frames public host programs send that no table documents: decoded
    /// so a capture reads whole and the simulator can answer them; never
    /// sent by the daemon.
    Vendor(VendorCommand),
}

/// can_id of the vendor SDK's enable-all standard frame (see [`VendorCommand::EnableAll`]).
pub const CAN_ID_VENDOR_ENABLE_ALL: u32 = 0xB1;

/// The undocumented frames of the vendor's MotorSDK (Stella-robot/GaiaHand,
/// `Software/MotorSDK/motor.py`, commit 8334adee).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VendorCommand {
    /// Standard frame, can_id 0xB1, data `[dev_id, op, 0 …]`: `enable_all_motors`
    /// sends `[0xFF, 1]` to enable and `[0xFF, 0]` to disable every device.
    /// The vendor document's printed `0xB155` example (SPEC errata 3) is this
    /// frame, with the broadcast head in place of the standard one.
    EnableAll { dev_id: u8, op: u8 },
    /// Heads `55 AF` / `55 B0`: 8 × i16 LE currents (the SDK's own raw
    /// scale, 0..3000), CRC over the values like every broadcast.
    CurrentBroadcast { group: Group, cur_ref: [i16; 8] },
}

impl VendorCommand {
    /// Whether its frame has a broadcast layout (the current broadcasts)
    /// or a standard one (the enable-all).
    pub fn is_broadcast(&self) -> bool {
        matches!(self, Self::CurrentBroadcast { .. })
    }

    /// What `jointd frame decode` calls it.
    pub fn name(&self) -> &'static str {
        match self {
            Self::EnableAll { .. } => "vendor enable-all (standard frame, can_id 0xB1)",
            Self::CurrentBroadcast { .. } => "vendor current broadcast (55 AF / 55 B0)",
        }
    }

    /// Why it is not in the tables.
    pub fn note(&self) -> &'static str {
        match self {
            Self::EnableAll { .. } => {
                "sent by the vendor's MotorSDK (enable_all_motors: [0xFF, 1] enable, [0xFF, 0] \
                 disable) and printed as the 0xB155 example of the vendor document; no table \
                 documents it (SPEC errata 3)"
            }
            Self::CurrentBroadcast { .. } => {
                "sent by the vendor's MotorSDK (set_motor_currents_broadcast); no table of the \
                 vendor document has these heads"
            }
        }
    }
}

/// `EN` of a control frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ControlOp {
    /// EN = 0: SET_REF on rev 2.0.8 firmware, a no-op on V2.0.1 (SPEC §4.1,
    /// errata 10). Public host programs for rev 2.0.8 send their angle
    /// commands this way, so it decodes; jointd itself never sends it, since
    /// it means different things on different firmware.
    SetRefRev208 = 0,
    Enable = 1,
    Disable = 2,
    SetRef = 3,
}

impl ControlOp {
    /// The name `jointd frame decode` and the raw frame views print.
    pub fn name(self) -> &'static str {
        match self {
            Self::SetRefRev208 => "set-ref (rev 2.0.8; a no-op in V2.0.1)",
            Self::Enable => "enable",
            Self::Disable => "disable",
            Self::SetRef => "set_ref",
        }
    }
}

/// SPEC §4.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Control {
    pub dev_id: u8,
    pub op: ControlOp,
    /// Q7 degrees.
    pub pos_ref: i16,
    /// Q15 of the base rotor speed; the speed limit in position mode.
    pub spd_ref: i16,
    /// Q15 current: reserved since firmware 1.2.0 (jointd sends 0 outside
    /// current mode); kept as it came so a decoder loses nothing, and the
    /// reference of rev 2.0.8's current mode.
    pub cur_ref: i16,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum JogDir {
    None = 0,
    /// +5°.
    Cw = 1,
    /// −3°.
    Ccw = 2,
}

/// SPEC §4.2.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Jog {
    pub dev_id: u8,
    pub dir: JogDir,
}

/// SPEC §4.3: a read or a write of one parameter of one device (or all).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    pub dev_id: u8,
    pub param: ConfigParam,
}

pub use super::values::{BaudLevel, CtrlMode, InfoBlock};

/// Index constants, defined beside the parameter table.
pub use super::params::index;

/// One parameter of SPEC §4.3 with its raw value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigParam {
    /// Reset request; the value is sent as given (the vendor documents none).
    Reboot(u16),
    ReadInfo(InfoBlock),
    UpdateFinZero,
    /// Stored to flash at once; the reply comes from the new id.
    SetId {
        new_id: u8,
    },
    /// Rotor encoder zero calibration: dangerous.
    UpdateEncZero,
    /// The device stops answering: dangerous.
    CommSilent(u16),
    CtrlMode(CtrlMode),
    PosKp(u16),
    PosKd(u16),
    SpdKp(u16),
    SpdKi(u16),
    /// Persist RAM parameters; the key must be [`WRITE_FLASH_KEY`] to take effect.
    WriteFlash {
        key: u8,
    },
    ReadFlash,
    BaudRate(BaudLevel),
    PosLpf(u8),
    MaxCur(u16),
    ProtectCurLimit(u16),
    ProtectCurLv1(u16),
    CurLv1DelayMs(u16),
    RecvCur(u16),
    CurRecvWinMs(u16),
    ColdTime(u8),
    PlusTime(u8),
    DrvOtC(u8),
    SpdLimit(u16),
    Sn(u16),
    /// An index this codec does not know; kept as it came.
    Other {
        index: u8,
        value: u16,
    },
}

impl ConfigParam {
    /// Which index and raw value go on the wire.
    pub fn index_value(&self) -> (u8, u16) {
        use index::*;
        match *self {
            Self::Reboot(v) => (REBOOT, v),
            Self::ReadInfo(b) => (b.index(), 0),
            Self::UpdateFinZero => (UPDATE_FIN_ZERO, 0),
            Self::SetId { new_id } => (SET_ID, u16::from(new_id) << 7),
            Self::UpdateEncZero => (UPDATE_ENC_ZERO, 0),
            Self::CommSilent(v) => (COMM_SILENT, v),
            Self::CtrlMode(m) => (CTRL_MODE_SW, m as u16),
            Self::PosKp(v) => (SET_POS_KP, v),
            Self::PosKd(v) => (SET_POS_KD, v),
            Self::SpdKp(v) => (SET_SPD_KP, v),
            Self::SpdKi(v) => (SET_SPD_KI, v),
            Self::WriteFlash { key } => (WRITE_FLASH, u16::from(key)),
            Self::ReadFlash => (READ_FLASH, 0),
            Self::BaudRate(l) => (BAUD_RATE, l as u16),
            Self::PosLpf(v) => (POS_LPF_LV, u16::from(v)),
            Self::MaxCur(v) => (MAX_CUR, v),
            Self::ProtectCurLimit(v) => (PROTECT_CUR_LIMIT, v),
            Self::ProtectCurLv1(v) => (PROTECT_CUR_LV1, v),
            Self::CurLv1DelayMs(v) => (CUR_LV1_DELAY, v),
            Self::RecvCur(v) => (RECV_CUR, v),
            Self::CurRecvWinMs(v) => (CUR_RECV_WIN, v),
            Self::ColdTime(v) => (COLD_TIME, u16::from(v)),
            Self::PlusTime(v) => (PLUS_TIME, u16::from(v)),
            Self::DrvOtC(v) => (DRV_OT, u16::from(v)),
            Self::SpdLimit(v) => (SPD_LIMIT, v),
            Self::Sn(v) => (SN, v),
            Self::Other { index, value } => (index, value),
        }
    }

    /// The typed parameter for an index and raw value. A value outside what
    /// the index's row allows (a 9-bit LPF level, an id not shifted by 7) is
    /// an error; an index without a row is kept as [`ConfigParam::Other`].
    pub fn from_index_value(idx: u8, value: u16) -> Result<Self, ProtocolError> {
        use index::*;
        if let Some(block) = InfoBlock::from_index(idx) {
            return Ok(Self::ReadInfo(block));
        }
        if let Some(row) = params::by_index(idx) {
            check_value(row, value)?;
        }
        // Checked above: an 8-bit row's value fits a byte.
        let byte = value as u8;
        let param = match idx {
            REBOOT => Self::Reboot(value),
            UPDATE_FIN_ZERO => Self::UpdateFinZero,
            SET_ID => Self::SetId {
                new_id: (value >> 7) as u8,
            },
            UPDATE_ENC_ZERO => Self::UpdateEncZero,
            COMM_SILENT => Self::CommSilent(value),
            CTRL_MODE_SW => Self::CtrlMode(
                CtrlMode::from_raw(byte)
                    .ok_or_else(|| bad("mode", value, "0 none, 1 speed, 2 position, 3 current"))?,
            ),
            SET_POS_KP => Self::PosKp(value),
            SET_POS_KD => Self::PosKd(value),
            SET_SPD_KP => Self::SpdKp(value),
            SET_SPD_KI => Self::SpdKi(value),
            WRITE_FLASH => Self::WriteFlash { key: byte },
            READ_FLASH => Self::ReadFlash,
            BAUD_RATE => Self::BaudRate(
                BaudLevel::from_raw(byte)
                    .ok_or_else(|| bad("baud level", value, "levels are 0..=4"))?,
            ),
            POS_LPF_LV => Self::PosLpf(byte),
            MAX_CUR => Self::MaxCur(value),
            PROTECT_CUR_LIMIT => Self::ProtectCurLimit(value),
            PROTECT_CUR_LV1 => Self::ProtectCurLv1(value),
            CUR_LV1_DELAY => Self::CurLv1DelayMs(value),
            RECV_CUR => Self::RecvCur(value),
            CUR_RECV_WIN => Self::CurRecvWinMs(value),
            COLD_TIME => Self::ColdTime(byte),
            PLUS_TIME => Self::PlusTime(byte),
            DRV_OT => Self::DrvOtC(byte),
            SPD_LIMIT => Self::SpdLimit(value),
            SN => Self::Sn(value),
            _ => Self::Other { index: idx, value },
        };
        Ok(param)
    }

    /// True for the reads (the device answers with an INFO block).
    pub fn is_read(&self) -> bool {
        matches!(self, Self::ReadInfo(_))
    }
}

/// Refuses a value its row does not allow: wider than the raw type, outside
/// the range, or (for an id) not shifted by 7.
fn check_value(row: &ParamRow, value: u16) -> Result<(), ProtocolError> {
    if row.raw == RawType::None {
        return Ok(()); // the index alone is the request; the value is ignored
    }
    if row.scale == Scale::DeviceIdQ7 && value & 0x7F != 0 {
        return Err(bad("set_id value", value, "must be new_id << 7 (Q7)"));
    }
    let (min, max) = row.range;
    if !(min..=max).contains(&value) {
        return Err(ProtocolError::OutOfTable {
            name: row.name,
            value,
            min,
            max,
        });
    }
    Ok(())
}

fn bad(field: &'static str, value: impl Into<i64>, why: &'static str) -> ProtocolError {
    ProtocolError::BadField {
        field,
        value: value.into(),
        why,
    }
}

/// A broadcast group: which eight devices a broadcast addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Group {
    /// Devices 1–8.
    Low,
    /// Devices 9–16.
    High,
}

impl Group {
    /// Id of the device in slot 0.
    pub fn first_id(self) -> u8 {
        match self {
            Group::Low => 1,
            Group::High => 9,
        }
    }

    /// The group and slot a device id occupies, if it is in one (ids 1..=16).
    pub fn slot_of(id: u8) -> Option<(Group, usize)> {
        match id {
            1..=8 => Some((Group::Low, usize::from(id - 1))),
            9..=16 => Some((Group::High, usize::from(id - 9))),
            _ => None,
        }
    }
}

/// `0xAB55` / `0xAC55`: eight target angles (Q7 degrees).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BroadcastPos {
    pub group: Group,
    pub pos_ref: [i16; 8],
}

/// `0xAD55` / `0xAE55`: eight speed references (Q15).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BroadcastSpd {
    pub group: Group,
    pub spd_ref: [i16; 8],
}

/// `0xB155` in the table layout: one u8 per device 1..16 (1 enable, 2 disable).
/// **Unverified** (SPEC errata 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BroadcastEnable {
    pub ops: [u8; 16],
    /// How its CRC was computed (SPEC errata 3: two readings are in use).
    pub crc: CrcCoverage,
}

impl Command {
    pub fn to_frame(&self) -> Frame {
        match self {
            Command::Control(c) => Frame::Standard(c.to_frame()),
            Command::Jog(j) => Frame::Standard(j.to_frame()),
            Command::Config(c) => Frame::Standard(c.to_frame()),
            Command::BroadcastPos(b) => Frame::Broadcast(b.to_frame()),
            Command::BroadcastSpd(b) => Frame::Broadcast(b.to_frame()),
            Command::BroadcastEnableUnverified(b) => Frame::Broadcast(BroadcastFrame {
                kind: BroadcastKind::Enable,
                values: b.ops,
                crc: b.crc,
            }),
            Command::Vendor(VendorCommand::EnableAll { dev_id, op }) => {
                let mut data = [0u8; 8];
                data[0] = *dev_id;
                data[1] = *op;
                Frame::Standard(StandardFrame {
                    can_id: CAN_ID_VENDOR_ENABLE_ALL,
                    data,
                })
            }
            Command::Vendor(VendorCommand::CurrentBroadcast { group, cur_ref }) => {
                Frame::Broadcast(BroadcastFrame {
                    kind: match group {
                        Group::Low => BroadcastKind::CurLow,
                        Group::High => BroadcastKind::CurHigh,
                    },
                    values: words_to_bytes(cur_ref),
                    crc: CrcCoverage::Values,
                })
            }
        }
    }

    pub fn encode(&self) -> FrameBytes {
        self.to_frame().encode()
    }

    /// The command a frame carries. A standard frame whose can_id is a reply's
    /// (low byte 0) is not a command.
    pub fn from_frame(frame: &Frame) -> Result<Command, ProtocolError> {
        match frame {
            Frame::Standard(f) => Self::from_standard(f),
            Frame::Broadcast(b) => Ok(Self::from_broadcast(b)),
        }
    }

    fn from_standard(f: &StandardFrame) -> Result<Command, ProtocolError> {
        match f.can_id {
            CAN_ID_JOG => Jog::from_data(&f.data).map(Command::Jog),
            CAN_ID_CONFIG => Config::from_data(&f.data).map(Command::Config),
            CAN_ID_VENDOR_ENABLE_ALL => Ok(Command::Vendor(VendorCommand::EnableAll {
                dev_id: f.data[0],
                op: f.data[1],
            })),
            id => match u8::try_from(id) {
                Ok(id8) if is_address(id8) => {
                    Control::from_data(id8, &f.data).map(Command::Control)
                }
                _ => Err(ProtocolError::UnknownCanId(id)),
            },
        }
    }

    fn from_broadcast(b: &BroadcastFrame) -> Command {
        let words = i16_words(&b.values);
        match b.kind {
            BroadcastKind::PosLow => Command::BroadcastPos(BroadcastPos {
                group: Group::Low,
                pos_ref: words,
            }),
            BroadcastKind::PosHigh => Command::BroadcastPos(BroadcastPos {
                group: Group::High,
                pos_ref: words,
            }),
            BroadcastKind::SpdLow => Command::BroadcastSpd(BroadcastSpd {
                group: Group::Low,
                spd_ref: words,
            }),
            BroadcastKind::SpdHigh => Command::BroadcastSpd(BroadcastSpd {
                group: Group::High,
                spd_ref: words,
            }),
            BroadcastKind::Enable => Command::BroadcastEnableUnverified(BroadcastEnable {
                ops: b.values,
                crc: b.crc,
            }),
            BroadcastKind::CurLow => Command::Vendor(VendorCommand::CurrentBroadcast {
                group: Group::Low,
                cur_ref: words,
            }),
            BroadcastKind::CurHigh => Command::Vendor(VendorCommand::CurrentBroadcast {
                group: Group::High,
                cur_ref: words,
            }),
        }
    }
}

fn i16_words(values: &[u8; 16]) -> [i16; 8] {
    std::array::from_fn(|i| i16::from_le_bytes([values[2 * i], values[2 * i + 1]]))
}

fn words_to_bytes(words: &[i16; 8]) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (chunk, w) in out.chunks_exact_mut(2).zip(words) {
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    out
}

impl Control {
    pub fn enable(dev_id: u8) -> Self {
        Self {
            dev_id,
            op: ControlOp::Enable,
            pos_ref: 0,
            spd_ref: 0,
            cur_ref: 0,
        }
    }

    pub fn disable(dev_id: u8) -> Self {
        Self {
            dev_id,
            op: ControlOp::Disable,
            pos_ref: 0,
            spd_ref: 0,
            cur_ref: 0,
        }
    }

    pub fn set_ref(dev_id: u8, pos_ref: i16, spd_ref: i16) -> Self {
        Self {
            dev_id,
            op: ControlOp::SetRef,
            pos_ref,
            spd_ref,
            cur_ref: 0,
        }
    }

    fn to_frame(self) -> StandardFrame {
        let mut data = [0u8; 8];
        data[0..2].copy_from_slice(&self.pos_ref.to_le_bytes());
        data[2..4].copy_from_slice(&self.spd_ref.to_le_bytes());
        data[4..6].copy_from_slice(&self.cur_ref.to_le_bytes());
        data[6] = self.op as u8;
        StandardFrame {
            can_id: u32::from(self.dev_id),
            data,
        }
    }

    fn from_data(dev_id: u8, data: &[u8; 8]) -> Result<Self, ProtocolError> {
        let op = match data[6] {
            0 => ControlOp::SetRefRev208,
            1 => ControlOp::Enable,
            2 => ControlOp::Disable,
            3 => ControlOp::SetRef,
            other => return Err(bad(
                "en",
                other,
                "0 set-ref (rev 2.0.8), 1 enable, 2 disable, 3 set_ref; anything else is a no-op",
            )),
        };
        Ok(Self {
            dev_id,
            op,
            pos_ref: i16::from_le_bytes([data[0], data[1]]),
            spd_ref: i16::from_le_bytes([data[2], data[3]]),
            cur_ref: i16::from_le_bytes([data[4], data[5]]),
        })
    }
}

impl Jog {
    fn to_frame(self) -> StandardFrame {
        let mut data = [0u8; 8];
        data[0] = self.dev_id;
        data[2] = self.dir as u8;
        StandardFrame {
            can_id: CAN_ID_JOG,
            data,
        }
    }

    fn from_data(data: &[u8; 8]) -> Result<Self, ProtocolError> {
        let dev_id = checked_address(data[0])?;
        let dir = match data[2] {
            0 => JogDir::None,
            1 => JogDir::Cw,
            2 => JogDir::Ccw,
            other => return Err(bad("dir", other, "0 none, 1 cw, 2 ccw")),
        };
        Ok(Self { dev_id, dir })
    }
}

impl Config {
    pub fn read(dev_id: u8, block: InfoBlock) -> Self {
        Self {
            dev_id,
            param: ConfigParam::ReadInfo(block),
        }
    }

    fn to_frame(self) -> StandardFrame {
        let (idx, value) = self.param.index_value();
        let mut data = [0u8; 8];
        data[0] = self.dev_id;
        data[1] = idx;
        data[4..6].copy_from_slice(&value.to_le_bytes());
        StandardFrame {
            can_id: CAN_ID_CONFIG,
            data,
        }
    }

    fn from_data(data: &[u8; 8]) -> Result<Self, ProtocolError> {
        let dev_id = checked_address(data[0])?;
        let value = u16::from_le_bytes([data[4], data[5]]);
        let param = ConfigParam::from_index_value(data[1], value)?;
        Ok(Self { dev_id, param })
    }
}

impl BroadcastPos {
    fn to_frame(self) -> BroadcastFrame {
        let kind = match self.group {
            Group::Low => BroadcastKind::PosLow,
            Group::High => BroadcastKind::PosHigh,
        };
        BroadcastFrame {
            kind,
            values: words_to_bytes(&self.pos_ref),
            crc: CrcCoverage::Values,
        }
    }
}

impl BroadcastSpd {
    fn to_frame(self) -> BroadcastFrame {
        let kind = match self.group {
            Group::Low => BroadcastKind::SpdLow,
            Group::High => BroadcastKind::SpdHigh,
        };
        BroadcastFrame {
            kind,
            values: words_to_bytes(&self.spd_ref),
            crc: CrcCoverage::Values,
        }
    }
}

fn checked_address(id: u8) -> Result<u8, ProtocolError> {
    if is_address(id) {
        Ok(id)
    } else {
        Err(ProtocolError::BadAddress(id))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_id_is_sent_as_q7() {
        let c = Config {
            dev_id: 1,
            param: ConfigParam::SetId { new_id: 10 },
        };
        let bytes = c.to_frame().data;
        assert_eq!(&bytes[4..6], &[0x00, 0x05]);
        assert!(ConfigParam::from_index_value(index::SET_ID, 1281).is_err());
        assert!(ConfigParam::from_index_value(index::SET_ID, 160 << 7).is_err());
    }

    #[test]
    fn control_with_en_zero_decodes_as_the_rev_2_0_8_set_ref() {
        let mut data = [0u8; 8];
        data[0..2].copy_from_slice(&(30 * 128i16).to_le_bytes());
        let c = Control::from_data(3, &data).expect("EN = 0 decodes");
        assert_eq!(c.op, ControlOp::SetRefRev208);
        assert_eq!((c.pos_ref, c.spd_ref), (30 * 128, 0));
        // It encodes back to the same bytes: the decoder can show what it read.
        assert_eq!(c.to_frame().data, data);
        data[6] = 4;
        assert!(Control::from_data(3, &data).is_err());
    }

    #[test]
    fn the_vendor_sdk_frames_decode_by_name_and_round_trip() {
        // MotorSDK's enable_all_motors(True): standard head, can_id 0xB1, [FF 01].
        let mut bytes = [0u8; 20];
        bytes[0..4].copy_from_slice(&[0x55, 0xAA, 0x00, 0x14]);
        bytes[4] = 0xB1;
        bytes[8] = 0xFF;
        bytes[9] = 0x01;
        let crc = crate::protocol::checksum::crc16(&bytes[4..16]);
        bytes[16..18].copy_from_slice(&crc.to_le_bytes());
        let frame = Frame::decode(&bytes).expect("a standard frame");
        let cmd = Command::from_frame(&frame).expect("named, not invalid");
        assert_eq!(
            cmd,
            Command::Vendor(VendorCommand::EnableAll {
                dev_id: 0xFF,
                op: 1
            })
        );
        assert_eq!(cmd.encode(), bytes);
        // set_motor_currents_broadcast: head 55 AF, CRC over the values.
        let cur = Command::Vendor(VendorCommand::CurrentBroadcast {
            group: Group::High,
            cur_ref: [100, 0, 0, 0, 0, 0, 0, 3000],
        });
        let bytes = cur.encode();
        assert_eq!(&bytes[0..2], &[0x55, 0xB0]);
        let crc = crate::protocol::checksum::crc16(&bytes[2..18]);
        assert_eq!(&bytes[18..20], &crc.to_le_bytes());
        assert_eq!(
            Command::from_frame(&Frame::decode(&bytes).unwrap()),
            Ok(cur)
        );
    }

    #[test]
    fn groups_map_ids_to_slots() {
        assert_eq!(Group::slot_of(1), Some((Group::Low, 0)));
        assert_eq!(Group::slot_of(16), Some((Group::High, 7)));
        assert_eq!(Group::slot_of(17), None);
        assert_eq!(Group::slot_of(0), None);
    }
}
