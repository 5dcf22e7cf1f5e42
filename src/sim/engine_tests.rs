//! The engine driven with made-up instants: exact wire timing, refereeing
//! and device effects, with no thread and no clock.

use std::time::{Duration, Instant};

use super::*;
use crate::protocol::status::fsm;
use crate::protocol::{BroadcastPos, Config, Control, Group, InfoBlock, Message, Reply};
use crate::sim::faults::Fault;

const BAUD: u32 = 500_000;
const F: Duration = Duration::from_micros(400);
const T: Duration = Duration::from_micros(100);

/// An engine whose devices have booted and announced by the returned instant.
fn booted(ids: &[u8]) -> (Engine, Instant) {
    let t0 = Instant::now();
    let mut cfg = SimConfig::new(ids.to_vec(), BAUD);
    cfg.align_time = Duration::from_millis(10);
    let mut e = Engine::new(&cfg, t0).unwrap();
    let t = t0 + Duration::from_millis(50);
    let hello = e.advance(t, Some(BAUD));
    assert_eq!(hello.len(), ids.len(), "one announcement per device");
    (e, t)
}

fn send(e: &mut Engine, at: Instant, cmds: &[Command]) {
    let bytes: Vec<u8> = cmds.iter().flat_map(|c| c.encode()).collect();
    e.on_host_bytes(&bytes, at, Some(BAUD));
}

fn reply_of(d: &Delivery) -> Option<Reply> {
    match Message::from_frame(&Frame::decode(&d.bytes).ok()?) {
        Ok(Message::Reply(r)) => Some(r),
        _ => None,
    }
}

fn read(id: u8) -> Command {
    Command::Config(Config::read(id, InfoBlock::Info01))
}

#[test]
fn a_poll_is_answered_after_frame_plus_turnaround_plus_frame() {
    let (mut e, t) = booted(&[1]);
    send(&mut e, t, &[read(1)]);
    assert!(e
        .advance(t + 2 * F + T - Duration::from_nanos(1), Some(BAUD))
        .is_empty());
    let out = e.advance(t + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].due, t + 2 * F + T);
    assert_eq!(reply_of(&out[0]).map(|r| (r.dev_id, r.index)), Some((1, 1)));
    let s = e.stats(t + Duration::from_millis(5));
    assert_eq!(
        s.busy,
        3 * F + T,
        "announcement + request + turnaround + reply"
    );
}

#[test]
fn a_frame_queued_into_a_reply_collides_and_is_not_applied() {
    let (mut e, t) = booted(&[1, 2]);
    send(&mut e, t, &[read(1), Command::Control(Control::enable(2))]);
    let out = e.advance(t + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out.len(), 1, "the garbled reply still reaches the host");
    assert!(reply_of(&out[0]).is_none());
    let s = e.stats(t + Duration::from_millis(5));
    assert_eq!(
        (s.collisions, s.collided_host_frames, s.collided_replies),
        (1, 1, 1)
    );
    let views = e.views(t + Duration::from_millis(5));
    assert_eq!(views[1].fsm, fsm::READY, "the collided enable did nothing");
}

#[test]
fn back_to_back_broadcasts_queue_and_all_apply() {
    let (mut e, t) = booted(&[1]);
    let frames: Vec<Command> = (1..=10)
        .map(|k| {
            Command::BroadcastPos(BroadcastPos {
                group: Group::Low,
                pos_ref: [k * 128; 8],
            })
        })
        .collect();
    send(&mut e, t, &frames);
    e.advance(t + 10 * F, Some(BAUD));
    let s = e.stats(t + 10 * F);
    assert_eq!(
        (s.queued_ahead, s.collisions, s.kinds.broadcast_pos),
        (9, 0, 10)
    );
    assert_eq!(
        s.busy - F,
        10 * F,
        "ten frames end to end, after the announcement"
    );
    assert!((e.views(t + 10 * F)[0].target_deg - 10.0).abs() < 1e-9);
}

#[test]
fn duplicate_ids_answer_together_and_collide() {
    let (mut e, t) = booted(&[4, 4]);
    send(&mut e, t, &[read(4)]);
    let out = e.advance(t + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out.len(), 1, "one garbled frame's worth of bytes");
    assert!(reply_of(&out[0]).is_none());
    assert_eq!(e.stats(t + Duration::from_millis(5)).collisions, 1);
}

#[test]
fn a_frame_at_another_baud_is_garbage_to_the_device() {
    let (mut e, t) = booted(&[1]);
    let bytes = Command::Control(Control::enable(1)).encode();
    e.on_host_bytes(&bytes, t, Some(230_400));
    e.advance(t + Duration::from_millis(5), Some(230_400));
    assert_eq!(e.stats(t).baud_mismatches, 1);
    assert_eq!(e.views(t + Duration::from_millis(5))[0].fsm, fsm::READY);
}

#[test]
fn dropped_and_corrupted_replies_are_counted() {
    let (mut e, t) = booted(&[1]);
    e.inject(
        Fault::DropReplies {
            dev_id: Some(1),
            rate: 1.0,
        },
        t,
    );
    send(&mut e, t, &[read(1)]);
    assert!(e
        .advance(t + Duration::from_millis(5), Some(BAUD))
        .is_empty());
    e.inject(Fault::ClearAll, t);
    e.inject(Fault::ExtraTurnaround(Duration::from_millis(1)), t);
    let t2 = t + Duration::from_millis(10);
    send(&mut e, t2, &[read(1)]);
    let out = e.advance(t2 + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out[0].due, t2 + 2 * F + T + Duration::from_millis(1));
    assert_eq!(e.stats(t2).dropped_replies, 1);
}

#[test]
fn enable_aligns_for_the_configured_time_then_runs() {
    let (mut e, t) = booted(&[1]);
    send(&mut e, t, &[Command::Control(Control::enable(1))]);
    e.advance(t + F, Some(BAUD));
    assert_eq!(e.views(t + F + Duration::from_millis(9))[0].fsm, fsm::ALIGN);
    assert_eq!(e.views(t + F + Duration::from_millis(10))[0].fsm, fsm::RUN);
}

#[test]
fn an_idle_line_is_not_busy() {
    let (e, t) = booted(&[1, 2, 3]);
    let a = e.stats(t);
    let b = e.stats(t + Duration::from_secs(1));
    assert_eq!(SimStats::occupancy(&a, &b), 0.0);
}

#[test]
fn a_frame_split_across_reads_starts_when_its_last_byte_arrives() {
    let (mut e, t) = booted(&[1]);
    let bytes = read(1).encode();
    e.on_host_bytes(&[0x00, 0x13], t, Some(BAUD));
    e.on_host_bytes(&bytes[..7], t, Some(BAUD));
    let late = t + Duration::from_millis(1);
    e.on_host_bytes(&bytes[7..], late, Some(BAUD));
    let out = e.advance(late + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out[0].due, late + 2 * F + T);
    assert_eq!(e.stats(late).skipped_bytes, 2, "leading garbage skipped");
}

#[test]
fn reads_to_all_get_no_answer_and_writes_to_all_answer_together() {
    let (mut e, t) = booted(&[1, 2]);
    send(&mut e, t, &[read(0xFF)]);
    assert!(e
        .advance(t + Duration::from_millis(5), Some(BAUD))
        .is_empty());
    let t2 = t + Duration::from_millis(10);
    let flash = Config {
        dev_id: 0xFF,
        param: crate::protocol::ConfigParam::WriteFlash { key: 0xA5 },
    };
    send(&mut e, t2, &[Command::Config(flash)]);
    let out = e.advance(t2 + Duration::from_millis(5), Some(BAUD));
    assert_eq!(out.len(), 1);
    assert!(reply_of(&out[0]).is_none(), "two RES at once collide");
    assert_eq!(e.stats(t2).collisions, 1);
}

#[test]
fn noise_reaches_the_host_every_period_in_time_order_until_stopped() {
    let (mut e, t) = booted(&[1]);
    let every = Duration::from_millis(2);
    e.inject(Fault::Noise(Some(every)), t);
    assert_eq!(e.next_event(), Some(t + every));
    send(&mut e, t + Duration::from_micros(2500), &[read(1)]);
    let out = e.advance(t + Duration::from_millis(5), Some(BAUD));
    let dues: Vec<Instant> = out.iter().map(|d| d.due).collect();
    let reply_at = t + Duration::from_micros(2500) + 2 * F + T;
    assert_eq!(dues, vec![t + every, reply_at, t + 2 * every]);
    assert!(reply_of(&out[0]).is_none() && reply_of(&out[1]).is_some());
    assert_eq!(e.stats(t).noise_bursts, 2);
    e.inject(Fault::Noise(None), t + Duration::from_millis(5));
    assert!(e
        .advance(t + Duration::from_millis(50), Some(BAUD))
        .is_empty());
}
