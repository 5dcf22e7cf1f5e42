//! Fuzzes the stream decoder with arbitrary bytes in arbitrary pieces, and
//! everything downstream of a decoded frame (typed message, JSON view).
#![no_main]

use jointd::protocol::frame_json::frame_to_json;
use jointd::protocol::{Frame, Message, StreamDecoder, FRAME_LEN};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The first byte picks the read size, as a port hands out odd pieces.
    let Some((&chunk, bytes)) = data.split_first() else { return };
    let chunk = usize::from(chunk % 64) + 1;
    let mut decoder = StreamDecoder::new();
    let mut frames = 0u64;
    for piece in bytes.chunks(chunk) {
        decoder.push(piece);
        while let Some((frame, raw)) = decoder.next_frame_with_bytes() {
            frames += 1;
            assert_eq!(frame.encode()[..FRAME_LEN - 2], raw[..FRAME_LEN - 2]);
            let _ = Message::from_frame(&frame);
            let _ = frame_to_json(&frame);
        }
    }
    let stats = decoder.stats();
    assert_eq!(stats.frames, frames);
    // Every byte is accounted for: in a frame, skipped, or still pending.
    assert_eq!(
        stats.frames * FRAME_LEN as u64 + stats.skipped_bytes + decoder.pending() as u64,
        bytes.len() as u64
    );
    for window in bytes.windows(FRAME_LEN) {
        if let Ok(f) = Frame::decode_slice(window) {
            let _ = Message::from_frame(&f);
        }
    }
});
