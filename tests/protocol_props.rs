//! Property tests of the protocol layer: every command and reply round-trips
//! through its bytes, and the stream decoder recovers exactly the valid frames
//! from any mix of frames and garbage, however the bytes are split.

use jointd::protocol::command::index;
use jointd::protocol::*;
use proptest::prelude::*;

fn address() -> impl Strategy<Value = u8> {
    prop_oneof![MIN_DEVICE_ID..=MAX_DEVICE_ID, Just(ALL_DEVICES)]
}

fn control() -> impl Strategy<Value = Command> {
    let op = prop_oneof![
        Just(ControlOp::SetRefRev208),
        Just(ControlOp::Enable),
        Just(ControlOp::Disable),
        Just(ControlOp::SetRef)
    ];
    (address(), op, any::<i16>(), any::<i16>(), any::<i16>()).prop_map(
        |(dev_id, op, pos_ref, spd_ref, cur_ref)| {
            Command::Control(Control {
                dev_id,
                op,
                pos_ref,
                spd_ref,
                cur_ref,
            })
        },
    )
}

fn jog() -> impl Strategy<Value = Command> {
    let dir = prop_oneof![Just(JogDir::None), Just(JogDir::Cw), Just(JogDir::Ccw)];
    (address(), dir).prop_map(|(dev_id, dir)| Command::Jog(Jog { dev_id, dir }))
}

/// Any index and value the typed layer accepts, so every `ConfigParam` variant appears.
fn config() -> impl Strategy<Value = Command> {
    let value = prop_oneof![
        0u16..8,
        Just(0xA5),
        (1u16..=159).prop_map(|id| id << 7),
        any::<u16>()
    ];
    (address(), 0u8..=40, value).prop_filter_map(
        "value not valid for index",
        |(dev_id, idx, value)| {
            let param = ConfigParam::from_index_value(idx, value).ok()?;
            Some(Command::Config(Config { dev_id, param }))
        },
    )
}

fn broadcast() -> impl Strategy<Value = Command> {
    let group = prop_oneof![Just(Group::Low), Just(Group::High)];
    prop_oneof![
        (group.clone(), any::<[i16; 8]>())
            .prop_map(|(group, pos_ref)| Command::BroadcastPos(BroadcastPos { group, pos_ref })),
        (group, any::<[i16; 8]>())
            .prop_map(|(group, spd_ref)| Command::BroadcastSpd(BroadcastSpd { group, spd_ref })),
        any::<[u8; 16]>()
            // Values only: a head-and-values CRC can match the SPEC's rule
            // too (1 in 65536), and then decodes as that; its unit test is in `frame`.
            .prop_map(|ops| Command::BroadcastEnableUnverified(BroadcastEnable {
                ops,
                crc: CrcCoverage::Values
            })),
    ]
}

fn command() -> impl Strategy<Value = Command> {
    prop_oneof![control(), jog(), config(), broadcast()]
}

fn reply_body() -> impl Strategy<Value = ReplyBody> {
    prop_oneof![
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info01(Info01::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info02(Info02::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info03(Gains::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info04(Info04::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info05(Info05::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(|d| ReplyBody::Info06(Info06::from_bytes(&d))),
        any::<[u8; 8]>().prop_map(ReplyBody::Info07),
        (
            prop::sample::select(vec![
                index::SET_ID,
                index::UPDATE_ENC_ZERO,
                index::WRITE_FLASH,
                index::BAUD_RATE
            ]),
            0u8..=1
        )
            .prop_map(|(index, code)| ReplyBody::Res { index, code }),
    ]
}

fn reply() -> impl Strategy<Value = Reply> {
    (MIN_DEVICE_ID..=MAX_DEVICE_ID, reply_body()).prop_map(|(id, body)| Reply::new(id, body))
}

fn any_frame() -> impl Strategy<Value = FrameBytes> {
    prop_oneof![
        command().prop_map(|c| c.encode()),
        reply().prop_map(|r| r.encode())
    ]
}

proptest! {
    #[test]
    fn commands_round_trip(cmd in command()) {
        let frame = Frame::decode(&cmd.encode()).expect("own frame decodes");
        prop_assert_eq!(Message::from_frame(&frame), Ok(Message::Command(cmd)));
    }

    #[test]
    fn replies_round_trip(r in reply()) {
        let frame = Frame::decode(&r.encode()).expect("own frame decodes");
        prop_assert_eq!(Message::from_frame(&frame), Ok(Message::Reply(r)));
        prop_assert_eq!(Reply::new(r.dev_id, r.body()), r);
    }

    #[test]
    fn any_reply_bytes_are_kept(dev_id in any::<u8>(), idx in any::<u8>(), data in any::<[u8; 8]>()) {
        let r = Reply { dev_id, index: idx, data };
        let frame = Frame::decode(&r.encode()).expect("own frame decodes");
        prop_assert_eq!(Message::from_frame(&frame), Ok(Message::Reply(r)));
    }

    #[test]
    fn single_frame_decode_never_panics(bytes in any::<[u8; 20]>()) {
        if let Ok(f) = Frame::decode(&bytes) {
            let _ = Message::from_frame(&f);
        }
    }

    #[test]
    fn stream_recovers_exactly_the_valid_frames(
        parts in prop::collection::vec((prop::collection::vec(any::<u8>(), 0..30), any_frame()), 0..20),
        tail in prop::collection::vec(any::<u8>(), 0..30),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..12),
    ) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for (garbage, frame) in &parts {
            stream.extend_from_slice(garbage);
            stream.extend_from_slice(frame);
            expected.push(*frame);
        }
        stream.extend_from_slice(&tail);

        let mut points: Vec<usize> = cuts.iter().map(|i| i.index(stream.len() + 1)).collect();
        points.push(stream.len());
        points.sort_unstable();

        let mut d = StreamDecoder::new();
        let mut found = Vec::new();
        let mut from = 0;
        for to in points {
            d.push(&stream[from..to]);
            from = to;
            while let Some((_, bytes)) = d.next_frame_with_bytes() {
                found.push(bytes);
            }
        }
        prop_assert_eq!(found, expected.clone());
        prop_assert_eq!(d.stats().frames, expected.len() as u64);
    }
}
