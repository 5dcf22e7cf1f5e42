//! `jointd frame decode|encode`: the protocol codec as a command-line tool,
//! for reading a serial capture by hand or crafting a frame for a test.

use std::fmt;

use crate::protocol::frame_json::{command_from_json, frame_to_json, FrameJsonError};
use crate::protocol::{DecoderStats, StreamDecoder};

/// Why a `frame` command could not do what was asked; printed on stderr, exit 2.
#[derive(Debug)]
pub enum FrameCliError {
    Hex(String),
    NoFrame {
        bytes: usize,
        stats: DecoderStats,
    },
    Json(FrameJsonError),
    /// An MCAP file that cannot be read (`frame decode --mcap`).
    Mcap(String),
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
            Self::Mcap(why) => write!(f, "MCAP recording: {why}"),
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

/// The frames of an MCAP recording (its `/jointd/BUS/frames` channels), one
/// JSON line each, as the frame log shows them: bus, wire time (Unix s),
/// direction, hex and the decoded frame. A recording cut short (no summary)
/// is read as far as its complete chunks go.
pub fn decode_mcap(path: &std::path::Path) -> Result<Vec<String>, FrameCliError> {
    let bytes =
        std::fs::read(path).map_err(|e| FrameCliError::Mcap(format!("{}: {e}", path.display())))?;
    let mut lines = Vec::new();
    for message in
        mcap::MessageStream::new(&bytes).map_err(|e| FrameCliError::Mcap(e.to_string()))?
    {
        let message = match message {
            Ok(m) => m,
            // A kill mid-chunk: what came before is whole.
            Err(e) if !lines.is_empty() => {
                eprintln!("note: the recording ends early ({e}); frames up to there listed");
                break;
            }
            Err(e) => return Err(FrameCliError::Mcap(e.to_string())),
        };
        let topic = &message.channel.topic;
        let Some(bus) = topic
            .strip_prefix("/jointd/")
            .and_then(|t| t.strip_suffix("/frames"))
        else {
            continue;
        };
        // JSON, or the same text in a std_msgs/String (a bag-compatible recording).
        let text = if message.channel.message_encoding == "cdr" {
            crate::rosmsg::string_from_cdr(&message.data)
                .map_err(|e| FrameCliError::Mcap(format!("{topic}: not a String: {e}")))?
                .into_bytes()
        } else {
            message.data.to_vec()
        };
        let v: serde_json::Value = serde_json::from_slice(&text)
            .map_err(|e| FrameCliError::Mcap(format!("{topic}: not a frame record: {e}")))?;
        let hex = v["hex"].as_str().unwrap_or_default();
        let raw = parse_hex(hex)?;
        let decoded = match <[u8; 20]>::try_from(raw.as_slice()) {
            Ok(bytes) => match crate::protocol::Frame::decode(&bytes) {
                Ok(frame) => frame_to_json(&frame),
                Err(e) => serde_json::json!({"kind": "garbage", "error": e.to_string()}),
            },
            Err(_) => {
                serde_json::json!({"kind": "garbage", "error": format!("{} bytes, not 20", raw.len())})
            }
        };
        let at = v["wire_time_ns"].as_u64().unwrap_or(message.log_time) as f64 / 1e9;
        lines.push(
            serde_json::json!({"bus": bus, "at": at, "direction": v["dir"], "hex": hex, "decoded": decoded})
                .to_string(),
        );
    }
    Ok(lines)
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
