//! `jointd frame decode|encode`: the protocol codec as a command-line tool,
//! for reading a serial capture by hand or crafting a frame for a test.

use std::fmt;

use crate::protocol::frame_json::{command_from_json, frame_to_json, FrameJsonError};
use crate::protocol::{DecoderStats, StreamDecoder};

/// Why a `frame` command could not do what was asked; printed on stderr, exit 2.
#[derive(Debug)]
pub enum FrameCliError {
    Hex(String),
    NoFrame { bytes: usize, stats: DecoderStats },
    Json(FrameJsonError),
}

impl fmt::Display for FrameCliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Hex(why) => write!(f, "bad hex input: {why}"),
            Self::NoFrame { bytes, stats } => write!(
                f,
                "no valid frame in {bytes} bytes ({} CRC errors, {} bytes skipped); \
                 frames start with 55 AA 00 14 (standard) or 55 AB/AC/AD/AE/B1 (broadcast)",
                stats.crc_errors, stats.skipped_bytes
            ),
            Self::Json(e) => write!(f, "bad frame description: {e}"),
        }
    }
}

impl std::error::Error for FrameCliError {}

/// Parses hex digits; spaces, `:`/`,`/`-` separators and `0x` prefixes are allowed.
pub fn parse_hex(text: &str) -> Result<Vec<u8>, FrameCliError> {
    let cleaned: String = text
        .split(|c: char| c.is_whitespace() || c == ':' || c == ',' || c == '-')
        .map(|tok| tok.trim_start_matches("0x").trim_start_matches("0X"))
        .collect();
    if let Some(bad) = cleaned.chars().find(|c| !c.is_ascii_hexdigit()) {
        return Err(FrameCliError::Hex(format!("`{bad}` is not a hex digit")));
    }
    if cleaned.len() % 2 != 0 {
        return Err(FrameCliError::Hex(format!(
            "odd number of hex digits ({}): every byte takes two",
            cleaned.len()
        )));
    }
    (0..cleaned.len())
        .step_by(2)
        .map(|i| {
            u8::from_str_radix(&cleaned[i..i + 2], 16)
                .map_err(|e| FrameCliError::Hex(e.to_string()))
        })
        .collect()
}

/// Decodes every frame in `hex`, one JSON line each, plus a summary of what
/// was skipped. Fails when no frame at all is found.
pub fn decode_hex(hex: &str) -> Result<(Vec<String>, DecoderStats, usize), FrameCliError> {
    let bytes = parse_hex(hex)?;
    let mut decoder = StreamDecoder::new();
    decoder.push(&bytes);
    let mut lines = Vec::new();
    while let Some(frame) = decoder.next_frame() {
        lines.push(frame_to_json(&frame).to_string());
    }
    let stats = decoder.stats();
    let trailing = decoder.pending();
    if lines.is_empty() {
        return Err(FrameCliError::NoFrame {
            bytes: bytes.len(),
            stats,
        });
    }
    Ok((lines, stats, trailing))
}

/// Encodes the host→device command described by `json` as spaced hex.
pub fn encode_json(json: &str) -> Result<String, FrameCliError> {
    let value: serde_json::Value =
        serde_json::from_str(json).map_err(|e| FrameCliError::Json(e.into()))?;
    let cmd = command_from_json(&value).map_err(FrameCliError::Json)?;
    Ok(crate::protocol::frame_json::hex(&cmd.encode()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_accepts_common_separators() {
        assert_eq!(
            parse_hex("55 aa:00,0x14").ok(),
            Some(vec![0x55, 0xAA, 0x00, 0x14])
        );
        assert!(parse_hex("5").is_err());
        assert!(parse_hex("zz").is_err());
    }
}
