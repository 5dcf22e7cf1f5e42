//! The line referee over a real pty: collisions, queueing, duplicate ids,
//! occupancy, and the modelled timing of a poll.

mod support;

use std::time::Duration;

use jointd::protocol::status::fsm;
use jointd::protocol::{BroadcastPos, Command, Config, Control, Group, InfoBlock};
use jointd::sim::SimStats;
use jointd::transport::tty::TtyPort;
use jointd::transport::Transport;
use support::sim::*;

fn read(id: u8) -> Command {
    Command::Config(Config::read(id, InfoBlock::Info01))
}

fn bcast(deg: i16) -> Command {
    Command::BroadcastPos(BroadcastPos {
        group: Group::Low,
        pos_ref: [deg * 128; 8],
    })
}

#[test]
fn a_host_frame_sent_during_a_reply_collides_and_neither_takes_effect() {
    let (sim, mut host) = pty(config(&[1, 2]));
    wait_for("announcements", || {
        (sim.stats().announcements == 2).then_some(())
    });
    host.drain(Duration::from_millis(20));
    // The enable queues right behind the poll, so it is on the wire while
    // device 1's reply (turnaround 100 µs < frame 400 µs) is too.
    host.send_many(&[read(1), Command::Control(Control::enable(2))]);
    wait_for("both frames off the line", || {
        (sim.stats().collided_replies == 1).then_some(())
    });
    let s = sim.stats();
    assert_eq!((s.collisions, s.collided_host_frames), (1, 1));
    assert!(
        host.recv(Duration::from_millis(50)).is_none(),
        "the reply arrived garbled"
    );
    assert!(host.decoder.stats().crc_errors + host.decoder.stats().skipped_bytes > 0);
    assert_eq!(
        sim.device(2).unwrap().fsm,
        fsm::READY,
        "the enable was not applied"
    );
    let log = sim.frame_log();
    assert_eq!(log.iter().filter(|f| f.collided).count(), 2);
}

#[test]
fn back_to_back_broadcasts_are_queued_not_collided() {
    let (sim, mut host) = pty(config(&[1, 2, 3]));
    wait_for("announcements", || {
        (sim.stats().announcements == 3).then_some(())
    });
    let frames: Vec<Command> = (1..=20).map(bcast).collect();
    host.send_many(&frames);
    wait_for("20 broadcasts", || {
        (sim.stats().kinds.broadcast_pos == 20).then_some(())
    });
    let s = sim.stats();
    assert_eq!(s.collisions, 0);
    assert!(s.queued_ahead >= 19, "queued {}", s.queued_ahead);
    for id in 1..=3 {
        assert!((sim.device(id).unwrap().target_deg - 20.0).abs() < 1e-9);
    }
    let host_frames: Vec<_> = sim
        .frame_log()
        .into_iter()
        .filter(|f| f.from_host)
        .collect();
    for pair in host_frames.windows(2) {
        assert_eq!(
            pair[1].start, pair[0].end,
            "each frame starts as the previous ends"
        );
    }
}

#[test]
fn duplicate_ids_collide() {
    let (sim, mut host) = pty(config(&[5, 5]));
    wait_for("announcements", || {
        (sim.stats().announcements == 2).then_some(())
    });
    host.drain(Duration::from_millis(20));
    assert!(host.read(5, InfoBlock::Info01).is_none());
    let s = sim.stats();
    assert_eq!((s.collisions, s.collided_replies, s.replies), (1, 2, 0));
}

#[test]
fn a_poll_takes_frame_turnaround_frame_of_simulated_wire() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("announcement");
    sim.clear_frame_log();
    host.read(1, InfoBlock::Info02).expect("reply");
    let log = sim.frame_log();
    let (req, rep) = (&log[0], &log[1]);
    assert!(req.from_host && !rep.from_host);
    assert_eq!((req.end - req.start).as_micros(), 400);
    assert_eq!(rep.start - req.end, Duration::from_micros(100));
    assert_eq!((rep.end - rep.start).as_micros(), 400);
}

#[test]
fn a_saturated_line_reads_full_and_an_idle_line_empty() {
    let (sim, host) = pty(config(&[1]));
    wait_for("announcement", || {
        (sim.stats().announcements == 1).then_some(())
    });
    let idle_from = sim.stats();
    // The idle span is what is measured here, not a wait for an event.
    std::thread::sleep(Duration::from_millis(50));
    let idle_to = sim.stats();
    assert!(SimStats::occupancy(&idle_from, &idle_to) < 0.01);
    drop(host);
    let path = sim.device_path().unwrap();
    let writer = std::thread::spawn(move || {
        let (mut port, _) = TtyPort::open(&path, BAUD).unwrap();
        let bytes: Vec<u8> = (0..1000).flat_map(|k| bcast(k % 100).encode()).collect();
        port.write_all(&bytes).unwrap();
    });
    let a = wait_for("200 frames", || {
        let s = sim.stats();
        (s.host_frames >= 200).then_some(s)
    });
    let b = wait_for("800 frames", || {
        let s = sim.stats();
        (s.host_frames >= 800).then_some(s)
    });
    writer.join().unwrap();
    let occ = SimStats::occupancy(&a, &b);
    assert!(occ >= 0.99, "saturated occupancy {occ}");
    assert_eq!(b.collisions, 0);
}
