//! Which reply's byte ended a full USB packet, and when the host read it.
//!
//! An FTDI chip with a latency timer longer than a USB frame holds a short
//! reply for its timer, so a reply's arrival says nothing of when its
//! write left the adapter. But it sends a full packet (62 bytes of data)
//! as soon as the 62nd byte is in, at the next USB frame: a read that is
//! exactly one packet dates the byte that ended it to the frame before the
//! read. That byte belongs to a reply; its offset in the stream of bytes
//! read says which one, once that reply is decoded, and the mark goes
//! with that reply (never looked up by its block: two polls of a block
//! may be in flight and their replies read together). The pipeline
//! ([`super::usb::pipeline`]) compares the read with the frame the byte
//! would have left in had its poll's write made its boundary: a sentinel
//! that slipped shows a frame later, as on adapters without a timer.
//!
//! Offsets count every byte read since the port opened, garbage included,
//! so a frame's place in the stream does not depend on how the bytes
//! before it decoded. A read of more or less than one packet (two packets
//! read late together, a short packet sent by the timer) dates nothing.

use std::collections::VecDeque;
use std::time::Instant;

use crate::protocol::FRAME_LEN;

/// Packet ends not yet matched to a reply: more than a few means the
/// stream went astray (a reply that never decoded), and the oldest go.
const MAX_ENDS: usize = 8;

/// A reply whose byte ended a full packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PacketMark {
    /// Which byte of the reply, 1 for its first, [`FRAME_LEN`] for its last.
    pub byte: u8,
    /// When the host read the packet.
    pub read_at: Instant,
}

/// The stream of bytes read from an adapter that sends full packets.
#[derive(Debug, Default)]
pub(crate) struct PacketEnds {
    /// Data bytes in a full packet; `None`: the adapter sends none to date.
    payload: Option<usize>,
    /// Bytes read since the port opened.
    total: u64,
    /// Offsets (exclusive ends) of reads that were exactly one packet.
    ends: VecDeque<(u64, Instant)>,
}

impl PacketEnds {
    /// For an adapter whose full packets carry `payload` data bytes.
    pub(crate) fn set_payload(&mut self, payload: Option<usize>) {
        self.payload = payload;
        self.ends.clear();
    }

    /// The port was (re)opened: offsets start again.
    pub(crate) fn reset(&mut self) {
        self.total = 0;
        self.ends.clear();
    }

    /// Bytes read since the port opened: where the next byte read sits in
    /// the stream.
    pub(crate) fn bytes_read(&self) -> u64 {
        self.total
    }

    /// `n` bytes were read just now (`now` is asked only of a read that
    /// was one packet: the link reads on the bus's hot path).
    pub(crate) fn read(&mut self, n: usize, now: impl FnOnce() -> Instant) {
        self.total += n as u64;
        if self.payload == Some(n) {
            if self.ends.len() == MAX_ENDS {
                self.ends.pop_front();
            }
            self.ends.push_back((self.total, now()));
        }
    }

    /// A reply was decoded, its last byte `pending` bytes before the end
    /// of what was read: its mark, if a packet ended inside it (a packet
    /// is longer than a frame, so at most one did).
    pub(crate) fn reply(&mut self, pending: usize) -> Option<PacketMark> {
        let end = self.total.saturating_sub(pending as u64);
        let start = end.saturating_sub(FRAME_LEN as u64);
        let mut mark = None;
        while let Some(&(at, read_at)) = self.ends.front() {
            if at > end {
                break;
            }
            self.ends.pop_front();
            if at > start {
                let byte = u8::try_from(at - start).unwrap_or(u8::MAX);
                mark = Some(PacketMark { byte, read_at });
            }
        }
        mark
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_read_of_one_packet_marks_the_reply_its_last_byte_is_in() {
        let t0 = Instant::now();
        let mut p = PacketEnds::default();
        p.set_payload(Some(62));
        // Replies 1-3 whole and 2 bytes of reply 4: one packet.
        p.read(62, || t0);
        for k in 1..=3 {
            assert_eq!(p.reply(62 - 20 * k), None);
        }
        // The rest of reply 4 comes in a short read.
        p.read(18, || t0 + Duration::from_millis(5));
        assert_eq!(
            p.reply(0),
            Some(PacketMark {
                byte: 2,
                read_at: t0
            })
        );
    }

    #[test]
    fn reads_of_other_sizes_date_nothing() {
        let t0 = Instant::now();
        let mut p = PacketEnds::default();
        p.set_payload(Some(62));
        p.read(124, || t0);
        p.read(20, || t0);
        assert!((1..=7).all(|k| p.reply(144 - 20 * k).is_none()));
        let mut none = PacketEnds::default();
        none.read(62, || t0);
        for pending in [42, 22, 2] {
            assert_eq!(none.reply(pending), None);
        }
        none.read(18, || t0);
        assert_eq!(none.reply(0), None, "no payload: no packets");
    }

    #[test]
    fn a_reply_no_packet_ends_in_takes_no_mark_of_a_later_reply_of_the_same_block() {
        let t0 = Instant::now();
        let mut p = PacketEnds::default();
        p.set_payload(Some(62));
        // Two polls of the same block in flight, their replies read
        // together: the first ends no packet, the second's 2nd byte ends one.
        p.read(62, || t0);
        let first = p.reply(42);
        assert_eq!(p.reply(22), None);
        p.read(18, || t0 + Duration::from_millis(1));
        let second = p.reply(0);
        // Each keeps its own, whichever the owner matches first.
        assert_eq!(first, None, "the later reply's mark");
        assert_eq!(second.map(|m| m.byte), Some(2));
    }
}
