//! CRC-16/CCITT-FALSE (the `crc` crate's `CRC_16_IBM_3740`), SPEC §2.
//!
//! A 16-entry slice table costs 8 KiB and makes the 12- and 16-byte CRCs of
//! our frames a handful of lookups, so the codec never matters next to the wire.

use crc::{Crc, Table, CRC_16_IBM_3740};

const CRC16: Crc<u16, Table<16>> = Crc::<u16, Table<16>>::new(&CRC_16_IBM_3740);

/// The checksum of `bytes` as stored (little-endian) in a frame.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_value_matches_spec() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }
}
