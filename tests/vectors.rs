//! Every frame of `tests/data/vectors.json` (a byte-identical copy of the
//! protocol's published test vectors, kept here so a clone tests alone) is
//! a test case: replies decode to exactly their `meaning`, host frames are
//! produced byte-for-byte from it, and the printed `0xB155` example is not
//! taken for a command. The file is read at run time, so a vector added
//! there is tested too; `JOINTD_VECTORS=path` tests another copy (the
//! protocol's own, to see whether this one is still the same).

use std::path::PathBuf;

use jointd::cli::parse_hex;
use jointd::protocol::checksum::crc16;
use jointd::protocol::frame_json::{command_from_json, frame_to_json};
use jointd::protocol::{Frame, FrameBytes, Message, Reply, StreamDecoder};
use serde_json::Value;

fn vectors_path() -> PathBuf {
    std::env::var_os("JOINTD_VECTORS")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/vectors.json")
        })
}

fn vectors() -> Vec<Value> {
    let path = vectors_path();
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let doc: Value = serde_json::from_str(&text).expect("vectors.json is JSON");
    let list = doc["vectors"]
        .as_array()
        .expect("`vectors` is an array")
        .clone();
    assert!(
        list.len() >= 20,
        "expected the full vector set, got {}",
        list.len()
    );
    list
}

fn bytes_of(v: &Value) -> FrameBytes {
    let hex = v["hex"].as_str().expect("hex");
    parse_hex(hex)
        .expect("valid hex")
        .try_into()
        .expect("20 bytes")
}

/// Tolerance of a number as printed: half a unit of its last decimal.
fn tolerance(expected: f64) -> f64 {
    let text = format!("{expected}");
    let decimals = text.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    0.5 * 10f64.powi(-decimals) + 1e-12
}

fn assert_matches(name: &str, key: &str, expected: &Value, got: Option<&Value>) {
    let got = got.unwrap_or_else(|| panic!("{name}: decoded JSON has no `{key}`"));
    match (expected, got) {
        (Value::Number(e), Value::Number(g)) => {
            let (e, g) = (
                e.as_f64().unwrap_or(f64::NAN),
                g.as_f64().unwrap_or(f64::NAN),
            );
            assert!(
                (e - g).abs() <= tolerance(e),
                "{name}: `{key}` expected {e}, decoded {g}"
            );
        }
        (Value::Array(e), Value::Array(g)) => {
            assert_eq!(e.len(), g.len(), "{name}: `{key}` length");
            for (i, (ev, gv)) in e.iter().zip(g).enumerate() {
                assert_matches(name, &format!("{key}[{i}]"), ev, Some(gv));
            }
        }
        (e, g) => assert_eq!(e, g, "{name}: `{key}`"),
    }
}

fn is_unverified(v: &Value) -> bool {
    v["meaning"]["kind"] == "unverified"
}

#[test]
fn every_vector_decodes_to_its_meaning() {
    for v in vectors().iter().filter(|v| !is_unverified(v)) {
        let name = v["name"].as_str().unwrap_or("?");
        let frame = Frame::decode(&bytes_of(v)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let json = frame_to_json(&frame);
        let meaning = v["meaning"].as_object().expect("meaning is an object");
        for (key, expected) in meaning {
            assert_matches(name, key, expected, json.get(key));
        }
        let direction = v["direction"].as_str();
        let message = Message::from_frame(&frame).unwrap_or_else(|e| panic!("{name}: {e}"));
        match message {
            Message::Reply(_) => assert_eq!(direction, Some("device_to_host"), "{name}"),
            Message::Command(_) => assert_eq!(direction, Some("host_to_device"), "{name}"),
        }
    }
}

#[test]
fn host_frames_are_produced_from_their_meaning() {
    let mut checked = 0;
    for v in vectors()
        .iter()
        .filter(|v| v["direction"] == "host_to_device" && !is_unverified(v))
    {
        let name = v["name"].as_str().unwrap_or("?");
        let cmd = command_from_json(&v["meaning"]).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(cmd.encode(), bytes_of(v), "{name}: encoded bytes");
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} host vectors");
}

#[test]
fn replies_re_encode_from_their_typed_body() {
    for v in vectors()
        .iter()
        .filter(|v| v["direction"] == "device_to_host")
    {
        let name = v["name"].as_str().unwrap_or("?");
        let bytes = bytes_of(v);
        let frame = Frame::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let Ok(Message::Reply(reply)) = Message::from_frame(&frame) else {
            panic!("{name}: not a reply");
        };
        assert_eq!(
            Reply::new(reply.dev_id, reply.body()).encode(),
            bytes,
            "{name}"
        );
    }
}

#[test]
fn broadcast_crcs_cover_the_sixteen_value_bytes() {
    for v in vectors()
        .iter()
        .filter(|v| v["meaning"]["kind"] == "broadcast")
    {
        let b = bytes_of(v);
        let stored = u16::from_le_bytes([b[18], b[19]]);
        assert_eq!(crc16(&b[2..18]), stored, "{}", v["name"]);
    }
}

#[test]
fn printed_b155_example_is_not_a_command() {
    let unverified: Vec<_> = vectors().into_iter().filter(is_unverified).collect();
    assert!(
        !unverified.is_empty(),
        "the printed 0xB155 example is in the vectors"
    );
    for v in unverified {
        let bytes = bytes_of(&v);
        assert!(
            Frame::decode(&bytes).is_err(),
            "{} decoded as a frame",
            v["name"]
        );
        let mut d = StreamDecoder::new();
        d.push(&bytes);
        assert_eq!(d.next_frame(), None, "{} found in a stream", v["name"]);
        assert_eq!(d.stats().crc_errors, 1);
    }
}

#[test]
fn all_vectors_back_to_back_decode_as_a_stream() {
    let list = vectors();
    let mut d = StreamDecoder::new();
    for v in &list {
        d.push(&bytes_of(v));
    }
    let mut found = Vec::new();
    while let Some(f) = d.next_frame() {
        found.push(f.encode());
    }
    let expected: Vec<_> = list
        .iter()
        .filter(|v| !is_unverified(v))
        .map(bytes_of)
        .collect();
    assert_eq!(found.len(), expected.len());
    for (f, e) in found.iter().zip(&expected) {
        // Standard frames' pad bytes are not covered by the CRC; all vectors carry 00 00.
        assert_eq!(f, e);
    }
}
