//! Errors of the protocol layer: bytes that are not a frame, frames that are
//! not a known command, and physical values that do not fit the wire.

use thiserror::Error;

pub use super::units::UnitError;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProtocolError {
    #[error("frame head {0:02X?} is neither a standard (55 AA 00 14) nor a broadcast (55 AB/AC/AD/AE/B1, or the vendor SDK's 55 AF/B0) head")]
    BadHead([u8; 4]),
    #[error("CRC mismatch: frame carries {found:#06x}, bytes give {computed:#06x}")]
    Crc { found: u16, computed: u16 },
    #[error("expected {expected} bytes, got {got}")]
    Length { expected: usize, got: usize },
    #[error(
        "can_id {0:#010x} is not a host command (control 0x01..0x9F/0xFF, jog 0xF0, config 0xA0, the vendor SDK's enable-all 0xB1)"
    )]
    UnknownCanId(u32),
    #[error("address {0:#04x} is neither a device id (1..=159) nor 0xFF (all)")]
    BadAddress(u8),
    #[error("{field} = {value} is not valid: {why}")]
    BadField {
        field: &'static str,
        value: i64,
        why: &'static str,
    },
    #[error("{name} = {value} is outside the range its index allows ({min}..={max})")]
    OutOfTable {
        name: &'static str,
        value: u16,
        min: u16,
        max: u16,
    },
    #[error(transparent)]
    Unit(#[from] UnitError),
}
