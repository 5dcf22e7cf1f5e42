//! Finds frames in a byte stream (SPEC §9: a byte count that is not a multiple
//! of 20 means interference).
//!
//! Bytes arrive in arbitrary pieces: a read may hold half a frame or three.
//! The decoder buffers them, looks for a valid head, and checks the CRC once
//! 20 bytes are there. On a bad CRC it drops a single byte and looks again, so
//! a valid frame that starts inside a corrupted one is still found. It never
//! panics and counts everything it throws away.

use super::frame::{classify_head, Frame, FrameBytes, Head, FRAME_LEN, SYNC};

/// What the decoder has seen since it was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    /// Frames with a valid head and CRC.
    pub frames: u64,
    /// Candidate frames (valid head) whose CRC did not match.
    pub crc_errors: u64,
    /// Bytes dropped while resynchronising (garbage, corrupted frames).
    pub skipped_bytes: u64,
}

#[derive(Debug, Default)]
pub struct StreamDecoder {
    buf: Vec<u8>,
    /// Start of the undecoded bytes in `buf`; compacted lazily so the hot
    /// path is an index bump, not a memmove per frame.
    start: usize,
    stats: DecoderStats,
}

impl StreamDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends bytes read from the line.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 && self.start >= self.buf.len() / 2 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// The next valid frame, or `None` until more bytes arrive.
    pub fn next_frame(&mut self) -> Option<Frame> {
        self.next_frame_with_bytes().map(|(frame, _)| frame)
    }

    /// Like [`Self::next_frame`], with the frame's 20 bytes as they arrived.
    pub fn next_frame_with_bytes(&mut self) -> Option<(Frame, FrameBytes)> {
        loop {
            let avail = &self.buf[self.start..];
            match classify_head(avail) {
                Head::Incomplete => return None,
                Head::Invalid => self.skip_to_next_sync(),
                Head::Standard | Head::Broadcast(_) => {
                    let bytes: FrameBytes = avail.get(..FRAME_LEN)?.try_into().ok()?;
                    match Frame::decode(&bytes) {
                        Ok(frame) => {
                            self.start += FRAME_LEN;
                            self.stats.frames += 1;
                            return Some((frame, bytes));
                        }
                        Err(_) => {
                            self.stats.crc_errors += 1;
                            self.skip(1);
                        }
                    }
                }
            }
        }
    }

    /// Drops bytes up to the next possible frame start (at least one byte).
    fn skip_to_next_sync(&mut self) {
        let avail = &self.buf[self.start..];
        let n = avail
            .iter()
            .skip(1)
            .position(|&b| b == SYNC)
            .map_or(avail.len(), |p| p + 1);
        self.skip(n);
    }

    fn skip(&mut self, n: usize) {
        self.start += n;
        self.stats.skipped_bytes += n as u64;
    }

    /// Bytes held that do not yet form a frame.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Throws away pending bytes (e.g. after the port was reopened); they count as skipped.
    pub fn clear(&mut self) {
        let n = self.pending();
        self.skip(n);
        self.buf.clear();
        self.start = 0;
    }

    pub fn stats(&self) -> DecoderStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Command, Control};

    fn frame() -> FrameBytes {
        Command::Control(Control::set_ref(1, 11520, 16384)).encode()
    }

    #[test]
    fn finds_a_frame_split_across_pushes() {
        let bytes = frame();
        let mut d = StreamDecoder::new();
        d.push(&bytes[..7]);
        assert_eq!(d.next_frame(), None);
        d.push(&bytes[7..]);
        assert!(d.next_frame().is_some());
        assert_eq!(d.pending(), 0);
    }

    #[test]
    fn resyncs_inside_a_corrupted_frame() {
        let good = frame();
        let mut corrupted = frame();
        corrupted[10] ^= 0xFF;
        let mut d = StreamDecoder::new();
        d.push(&corrupted[..12]);
        d.push(&good);
        assert_eq!(d.next_frame().map(|f| f.encode()), Some(good));
        assert_eq!(d.stats().crc_errors, 1);
        assert_eq!(d.stats().skipped_bytes, 12);
    }

    #[test]
    fn garbage_only_is_counted_and_dropped() {
        let mut d = StreamDecoder::new();
        d.push(&[0x00, 0x55, 0x01, 0xFF, 0x55]);
        assert_eq!(d.next_frame(), None);
        assert_eq!(d.stats().skipped_bytes, 4);
        assert_eq!(d.pending(), 1);
    }
}
