//! The two 20-byte frame layouts of SPEC §3 and their CRC rules.
//!
//! This layer knows only layout: a standard frame is `can_id` + 8 data bytes,
//! a broadcast frame is a head and 16 value bytes. What the bytes mean is
//! [`super::command`]'s and [`super::reply`]'s business.

use super::checksum::crc16;
use super::error::ProtocolError;

/// Every frame is exactly this long, in both directions.
pub const FRAME_LEN: usize = 20;
/// One frame's bytes.
pub type FrameBytes = [u8; FRAME_LEN];

/// First byte of every head.
pub const SYNC: u8 = 0x55;
/// Head of a standard frame (u32 LE `0x1400AA55`).
pub const STANDARD_HEAD: [u8; 4] = [0x55, 0xAA, 0x00, 0x14];

/// A frame as laid out on the wire, CRC already checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    Standard(StandardFrame),
    Broadcast(BroadcastFrame),
}

/// SPEC §3.1: head, `can_id`, 8 data bytes, CRC over bytes 4..16, pad.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StandardFrame {
    pub can_id: u32,
    pub data: [u8; 8],
}

/// SPEC §3.2: 2-byte head, 16 value bytes, CRC over bytes 2..18.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BroadcastFrame {
    pub kind: BroadcastKind,
    pub values: [u8; 16],
    /// Which bytes the CRC covers: always the values, except for `0xB155`
    /// frames as public rev 2.0.8 host programs send them.
    pub crc: CrcCoverage,
}

/// The bytes a broadcast frame's CRC covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum CrcCoverage {
    /// Bytes 2..18, the 16 value bytes: SPEC §3.2's rule, the only one jointd sends.
    #[default]
    Values,
    /// Bytes 0..18, head included: how a public rev 2.0.8 host firmware
    /// (E1_Hand_G474) computes the CRC of `0xB155` (SPEC errata 3). Accepted
    /// for `0xB155` only, where the SPEC has no verified rule to protect.
    HeadAndValues,
}

impl CrcCoverage {
    /// What `jointd frame decode` says about it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Values => "CRC over bytes 2..18 (the values; SPEC §3.2)",
            Self::HeadAndValues => "CRC over bytes 0..18 (head and values; E1_Hand_G474's reading)",
        }
    }

    fn covered(self, frame: &[u8]) -> &[u8] {
        match self {
            Self::Values => &frame[2..18],
            Self::HeadAndValues => &frame[0..18],
        }
    }
}

/// The broadcast heads, as the u16 LE value of bytes 0..2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum BroadcastKind {
    /// Target angles of devices 1–8.
    PosLow = 0xAB55,
    /// Target angles of devices 9–16.
    PosHigh = 0xAC55,
    /// Speed references of devices 1–8.
    SpdLow = 0xAD55,
    /// Speed references of devices 9–16.
    SpdHigh = 0xAE55,
    /// Enable/disable of devices 1–16. **Unverified** (SPEC errata 3): the
    /// vendor's table and its printed example disagree; the daemon never sends it.
    Enable = 0xB155,
    /// Currents of devices 1–8. **Undocumented**: no table of the vendor
    /// document has it; the vendor's MotorSDK (Stella-robot/GaiaHand,
    /// `Software/MotorSDK/motor.py`) sends it. Decoded so a capture reads
    /// whole; the daemon never sends it.
    CurLow = 0xAF55,
    /// Currents of devices 9–16 (undocumented, as [`Self::CurLow`]).
    CurHigh = 0xB055,
}

impl BroadcastKind {
    pub const ALL: [BroadcastKind; 7] = [
        Self::PosLow,
        Self::PosHigh,
        Self::SpdLow,
        Self::SpdHigh,
        Self::Enable,
        Self::CurLow,
        Self::CurHigh,
    ];

    /// False for heads no table of the vendor document has (seen in public
    /// host programs only).
    pub fn documented(self) -> bool {
        !matches!(self, Self::CurLow | Self::CurHigh)
    }

    /// The head as the u16 LE value of bytes 0..2 (`head2` in the vectors).
    pub fn head2(self) -> u16 {
        self as u16
    }

    /// The kind whose second head byte is `byte`, if any.
    pub fn from_second_byte(byte: u8) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|k| (k.head2() >> 8) as u8 == byte)
    }
}

impl StandardFrame {
    pub fn encode(&self) -> FrameBytes {
        let mut out = [0u8; FRAME_LEN];
        out[0..4].copy_from_slice(&STANDARD_HEAD);
        out[4..8].copy_from_slice(&self.can_id.to_le_bytes());
        out[8..16].copy_from_slice(&self.data);
        let crc = crc16(&out[4..16]);
        out[16..18].copy_from_slice(&crc.to_le_bytes());
        out
    }
}

impl BroadcastFrame {
    pub fn encode(&self) -> FrameBytes {
        let mut out = [0u8; FRAME_LEN];
        out[0..2].copy_from_slice(&self.kind.head2().to_le_bytes());
        out[2..18].copy_from_slice(&self.values);
        let crc = crc16(self.crc.covered(&out));
        out[18..20].copy_from_slice(&crc.to_le_bytes());
        out
    }
}

impl Frame {
    pub fn encode(&self) -> FrameBytes {
        match self {
            Frame::Standard(f) => f.encode(),
            Frame::Broadcast(f) => f.encode(),
        }
    }

    /// Decodes one frame, checking head and CRC. The pad bytes of a standard
    /// frame are not covered by its CRC and are ignored.
    pub fn decode(bytes: &FrameBytes) -> Result<Frame, ProtocolError> {
        match classify_head(bytes) {
            Head::Standard => decode_standard(bytes).map(Frame::Standard),
            Head::Broadcast(kind) => decode_broadcast(kind, bytes).map(Frame::Broadcast),
            Head::Invalid | Head::Incomplete => Err(ProtocolError::BadHead([
                bytes[0], bytes[1], bytes[2], bytes[3],
            ])),
        }
    }

    /// Decodes from a slice that must be exactly [`FRAME_LEN`] bytes long.
    pub fn decode_slice(bytes: &[u8]) -> Result<Frame, ProtocolError> {
        let arr: &FrameBytes = bytes.try_into().map_err(|_| ProtocolError::Length {
            expected: FRAME_LEN,
            got: bytes.len(),
        })?;
        Frame::decode(arr)
    }
}

fn decode_standard(bytes: &FrameBytes) -> Result<StandardFrame, ProtocolError> {
    check_crc(&bytes[4..16], [bytes[16], bytes[17]])?;
    let can_id = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
    let mut data = [0u8; 8];
    data.copy_from_slice(&bytes[8..16]);
    Ok(StandardFrame { can_id, data })
}

fn decode_broadcast(
    kind: BroadcastKind,
    bytes: &FrameBytes,
) -> Result<BroadcastFrame, ProtocolError> {
    let stored = [bytes[18], bytes[19]];
    let crc = match check_crc(CrcCoverage::Values.covered(bytes), stored) {
        Ok(()) => CrcCoverage::Values,
        Err(e) if kind != BroadcastKind::Enable => return Err(e),
        Err(e) => check_crc(CrcCoverage::HeadAndValues.covered(bytes), stored)
            .map(|()| CrcCoverage::HeadAndValues)
            // The error names the SPEC's rule, not the variant's.
            .map_err(|_| e)?,
    };
    let mut values = [0u8; 16];
    values.copy_from_slice(&bytes[2..18]);
    Ok(BroadcastFrame { kind, values, crc })
}

fn check_crc(covered: &[u8], stored: [u8; 2]) -> Result<(), ProtocolError> {
    let found = u16::from_le_bytes(stored);
    let computed = crc16(covered);
    if found == computed {
        Ok(())
    } else {
        Err(ProtocolError::Crc { found, computed })
    }
}

/// What the first bytes of a buffer say about the frame that may start there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Head {
    Standard,
    Broadcast(BroadcastKind),
    /// A prefix of a valid head: more bytes are needed to tell.
    Incomplete,
    Invalid,
}

/// Looks at up to the first four bytes of `bytes` (which may be shorter).
pub(crate) fn classify_head(bytes: &[u8]) -> Head {
    match bytes {
        [] => Head::Incomplete,
        [first, ..] if *first != SYNC => Head::Invalid,
        [_] => Head::Incomplete,
        [_, second, rest @ ..] if *second == STANDARD_HEAD[1] => {
            let wanted = &STANDARD_HEAD[2..2 + rest.len().min(2)];
            if &rest[..wanted.len()] != wanted {
                Head::Invalid
            } else if wanted.len() < 2 {
                Head::Incomplete
            } else {
                Head::Standard
            }
        }
        [_, second, ..] => match BroadcastKind::from_second_byte(*second) {
            Some(kind) => Head::Broadcast(kind),
            None => Head::Invalid,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heads_are_classified_from_partial_input() {
        assert_eq!(classify_head(&[]), Head::Incomplete);
        assert_eq!(classify_head(&[0x55]), Head::Incomplete);
        assert_eq!(classify_head(&[0x55, 0xAA, 0x00]), Head::Incomplete);
        assert_eq!(classify_head(&[0x55, 0xAA, 0x00, 0x14]), Head::Standard);
        assert_eq!(classify_head(&[0x55, 0xAA, 0x01]), Head::Invalid);
        assert_eq!(classify_head(&[0x54]), Head::Invalid);
        assert_eq!(
            classify_head(&[0x55, 0xAB]),
            Head::Broadcast(BroadcastKind::PosLow)
        );
        assert_eq!(
            classify_head(&[0x55, 0xAF]),
            Head::Broadcast(BroadcastKind::CurLow)
        );
        assert_eq!(classify_head(&[0x55, 0xB2]), Head::Invalid);
    }

    #[test]
    fn standard_frame_round_trips_and_ignores_pad() {
        let f = StandardFrame {
            can_id: 0xA0,
            data: [2, 1, 0, 0, 0, 0, 0, 0],
        };
        let mut bytes = f.encode();
        assert_eq!(Frame::decode(&bytes), Ok(Frame::Standard(f)));
        bytes[19] = 0x7E;
        assert_eq!(Frame::decode(&bytes), Ok(Frame::Standard(f)));
        bytes[9] ^= 1;
        assert!(matches!(
            Frame::decode(&bytes),
            Err(ProtocolError::Crc { .. })
        ));
    }

    #[test]
    fn only_the_enable_broadcast_may_carry_its_crc_over_the_head() {
        for kind in BroadcastKind::ALL {
            let f = BroadcastFrame {
                kind,
                values: [1; 16],
                crc: CrcCoverage::HeadAndValues,
            };
            let bytes = f.encode();
            assert_ne!(
                bytes,
                BroadcastFrame {
                    crc: CrcCoverage::Values,
                    ..f
                }
                .encode(),
                "the two rules give different CRCs"
            );
            let decoded = Frame::decode(&bytes);
            if kind == BroadcastKind::Enable {
                assert_eq!(decoded, Ok(Frame::Broadcast(f)));
            } else {
                assert!(
                    matches!(decoded, Err(ProtocolError::Crc { .. })),
                    "{kind:?}"
                );
            }
        }
    }

    #[test]
    fn decode_slice_rejects_wrong_length() {
        assert_eq!(
            Frame::decode_slice(&[0x55; 19]),
            Err(ProtocolError::Length {
                expected: 20,
                got: 19
            })
        );
    }
}
