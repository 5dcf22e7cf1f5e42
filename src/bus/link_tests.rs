//! The link's unit tests: reply matching, the frame clock's samples, a hung-up port.

use super::*;
use crate::bus::handle::BusSnapshot;
use crate::protocol::{Config, InfoBlock, ReplyBody};
use crate::transport::memory;

fn link_pair() -> (Link, memory::MemoryPort) {
    let (host, dev) = memory::pair(500_000);
    let shared = BusShared::new("t".into(), BusSnapshot::new("t", "mem", 500_000));
    let mut link = Link::new(
        Some(Box::new(host)),
        None,
        500_000,
        &Timing::default(),
        shared,
    );
    link.open().unwrap();
    (link, dev)
}

#[test]
fn the_wanted_reply_is_returned_and_others_kept() {
    let (mut link, mut dev) = link_pair();
    link.send(&[Command::Config(Config::read(3, InfoBlock::Info02))])
        .unwrap();
    let other = Reply::new(9, ReplyBody::Res { index: 13, code: 1 });
    let wanted = Reply::new(3, ReplyBody::Unknown { index: 2 });
    let mut bytes = other.encode().to_vec();
    bytes.extend_from_slice(&[0x55, 0x00, 0x13]); // garbage between frames
    bytes.extend_from_slice(&wanted.encode());
    dev.write_all(&bytes).unwrap();
    let want = Want {
        dev_id: 3,
        index: 2,
    };
    let got = link
        .wait(Some(want), Instant::now() + Duration::from_millis(50))
        .unwrap();
    assert_eq!(got.map(|(r, _)| r), Some(wanted));
    assert_eq!(link.inbox.len(), 1);
    assert_eq!(link.counters.frames_tx_config, 1);
    assert_eq!(link.counters.frames_rx, 2);
}

/// Device 3's INFO_01 in state `fsm`.
fn info01_of_3(fsm: u8) -> Reply {
    Reply::new(
        3,
        ReplyBody::Info01(crate::protocol::Info01 {
            fsm,
            ..Default::default()
        }),
    )
}

const INFO01_OF_3: Want = Want {
    dev_id: 3,
    index: 1,
};

/// An announcement an adapter held and passed on with the reply
/// precedes it: the later of the two answers the read.
#[test]
fn of_two_wanted_replies_read_together_the_later_answers() {
    let (mut link, mut dev) = link_pair();
    link.send(&[Command::Config(Config::read(3, InfoBlock::Info01))])
        .unwrap();
    let (announced, reply) = (info01_of_3(0), info01_of_3(7));
    let mut bytes = announced.encode().to_vec();
    bytes.extend_from_slice(&reply.encode());
    dev.write_all(&bytes).unwrap();
    let want = INFO01_OF_3;
    let got = link
        .wait(Some(want), Instant::now() + Duration::from_millis(50))
        .unwrap();
    assert_eq!(got.map(|(r, _)| r), Some(reply));
    let kept: Vec<Reply> = link.inbox.iter().map(|h| h.reply).collect();
    assert_eq!(kept, vec![announced]);
}

/// An announcement whose first bytes were read before the request was
/// written, its end held by an adapter until after: it was on the wire
/// before the request, so it answers nothing, whatever read its end came in.
#[test]
fn a_reply_begun_before_the_request_was_written_does_not_answer_it() {
    let (mut link, mut dev) = link_pair();
    let (announced, reply) = (info01_of_3(0), info01_of_3(7));
    let bytes = announced.encode();
    let (head, tail) = bytes.split_at(2);
    dev.write_all(head).unwrap();
    link.wait(None, Instant::now() + Duration::from_millis(5))
        .unwrap();
    assert_eq!(link.decoder.pending(), 2, "the announcement's head is in");
    link.send(&[Command::Config(Config::read(3, InfoBlock::Info01))])
        .unwrap();
    dev.write_all(tail).unwrap();
    let want = INFO01_OF_3;
    let got = link
        .wait(Some(want), Instant::now() + Duration::from_millis(20))
        .unwrap();
    assert_eq!(got, None, "the announcement's end is no answer");
    let kept: Vec<Reply> = link.inbox.iter().map(|h| h.reply).collect();
    assert_eq!(kept, vec![announced]);
    dev.write_all(&reply.encode()).unwrap();
    let got = link
        .wait(Some(want), Instant::now() + Duration::from_millis(50))
        .unwrap();
    assert_eq!(got.map(|(r, _)| r), Some(reply));
}

/// Bytes found waiting came at some earlier instant: only bytes a
/// read woke on date an adapter's boundary.
#[test]
fn only_bytes_a_read_woke_on_date_a_boundary() {
    let (mut link, mut dev) = link_pair();
    let reply = Reply::new(9, ReplyBody::Res { index: 13, code: 1 });
    dev.write_all(&reply.encode()).unwrap();
    link.wait(None, Instant::now() + Duration::from_millis(5))
        .unwrap();
    assert_eq!(link.inbox.len(), 1);
    assert_eq!(link.take_woke_on_bytes().count(), 0);
    // Written while the link waits (a few tries: a thread may be
    // slower to start than the wait is long).
    let mut woke = false;
    for _ in 0..5 {
        let writer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            dev.write_all(&reply.encode()).unwrap();
            dev
        });
        link.wait(None, Instant::now() + Duration::from_millis(200))
            .unwrap();
        dev = writer.join().unwrap();
        if link.take_woke_on_bytes().count() == 1 {
            woke = true;
            break;
        }
    }
    assert!(woke, "no read woke on the bytes");
}

#[test]
fn silence_times_out_and_hangup_is_an_error() {
    let (mut link, dev) = link_pair();
    let soon = Instant::now() + Duration::from_millis(2);
    assert_eq!(link.wait(None, soon).unwrap(), None);
    dev.set_hung_up(true);
    assert!(link
        .wait(None, Instant::now() + Duration::from_millis(50))
        .is_err());
    link.close();
    assert!(link.open().is_err(), "still hung up");
    dev.set_hung_up(false);
    assert!(link.open().is_ok(), "probed back up");
}
