use super::*;
use crate::protocol::command::index;
use crate::protocol::ReplyBody;

#[test]
fn the_only_frame_made_is_a_read() {
    for block in InfoBlock::ALL {
        let frame = Frame::decode(&read_frame(3, block)).expect("a valid frame");
        let Ok(Command::Config(c)) = Command::from_frame(&frame) else {
            panic!("not a config frame: {frame:?}")
        };
        assert!(c.param.is_read(), "{block:?} is not a read");
        assert_eq!(c.dev_id, 3);
    }
    // SPEC §4.3's vector: the INFO_01 read of device 2.
    let want = [
        0x55, 0xAA, 0x00, 0x14, 0xA0, 0x00, 0x00, 0x00, 0x02, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00,
        0x00, 0x3F, 0x77, 0x00, 0x00,
    ];
    assert_eq!(read_frame(2, InfoBlock::Info01), want);
    assert_eq!(InfoBlock::Info01.index(), index::INFO_01_R);
}

fn sent_at(at: Instant) -> Sent {
    Sent {
        id: 2,
        block: InfoBlock::Info01,
        bytes: read_frame(2, InfoBlock::Info01),
        at,
    }
}

fn reply_of(id: u8) -> FrameBytes {
    Reply::new(id, ReplyBody::Info01(crate::protocol::Info01::default())).encode()
}

#[test]
fn each_frame_is_sorted_against_the_read() {
    let t0 = Instant::now();
    let tf = Duration::from_micros(400);
    let sent = sent_at(t0);
    let sort_at = |bytes: FrameBytes, us: u64| {
        let frame = Frame::decode(&bytes).expect("valid");
        let recent = VecDeque::from([read_frame(9, InfoBlock::Info02)]);
        sort(
            &sent,
            &recent,
            &frame,
            &bytes,
            t0 + Duration::from_micros(us),
            tf,
        )
    };
    assert!(matches!(sort_at(reply_of(2), 1_000), Sorted::Answer(r) if r.dev_id == 2));
    assert_eq!(
        sort_at(reply_of(2), 500),
        Sorted::Late,
        "before two frames could pass"
    );
    assert_eq!(sort_at(reply_of(3), 1_000), Sorted::Unasked);
    assert_eq!(sort_at(sent.bytes, 450), Sorted::Echo);
    assert_eq!(
        sort_at(read_frame(5, InfoBlock::Info02), 450),
        Sorted::Foreign
    );
    assert_eq!(
        sort_at(read_frame(9, InfoBlock::Info02), 450),
        Sorted::Echo,
        "an earlier read's"
    );
}

/// A memory line with a scripted device end: an echo, two replies and
/// garbage after a read made a millisecond ago.
#[test]
fn hear_counts_two_replies_an_echo_and_garbage() {
    let (mut host, mut dev) = crate::transport::memory::pair(500_000);
    // A window no stall of this thread outlasts: the read ends on the
    // replies (shortly after the first), not on the window.
    let timing = Timing {
        reply_margin_us: 60_000_000,
        ..Timing::default()
    };
    let mut ex = Exchange::new(&mut host, AdapterModel::Native, &timing);
    let ago = Instant::now()
        .checked_sub(Duration::from_millis(1))
        .expect("a millisecond ago");
    let sent = sent_at(ago);
    let mut back = sent.bytes.to_vec();
    back.extend_from_slice(&reply_of(2));
    back.extend_from_slice(&reply_of(2));
    back.extend_from_slice(&[0x00, 0x13, 0x07]);
    dev.write_all(&back).expect("echo, two replies, garbage");
    let heard = ex.hear(&sent).expect("hear");
    assert_eq!(heard.replies, 2, "two devices answered");
    assert!(heard.reply.is_some() && heard.after.is_some());
    assert_eq!(heard.garbage, 3);
    assert_eq!((ex.tally.echoes, ex.tally.late_replies), (1, 0));
}
