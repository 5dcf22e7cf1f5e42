//! The owner's reply wait against an in-memory line: what it learns of
//! the reply lag.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::config::BusConfig;
use crate::bus::handle::{BusShared, BusSnapshot};
use crate::bus::link::Link;
use crate::bus::wire::Want;
use crate::protocol::{Config, InfoBlock, Reply, ReplyBody};
use crate::transport::memory::{self, MemoryPort};
use crate::transport::Transport;

use super::Ctx;

const BAUD: u32 = 2_000_000;

/// An owner context on an open in-memory line at [`BAUD`], and the
/// line's device end.
fn ctx(tweak: impl FnOnce(&mut BusConfig)) -> (Ctx, MemoryPort) {
    let mut cfg = BusConfig::new("t", "mem", BAUD);
    cfg.timing.turnaround_us = 0;
    tweak(&mut cfg);
    let (host, dev) = memory::pair(BAUD);
    let shared = BusShared::new("t".into(), BusSnapshot::new("t", "mem", BAUD));
    let mut link = Link::new(
        Some(Box::new(host)),
        None,
        BAUD,
        &cfg.timing,
        Arc::clone(&shared),
    );
    link.open().expect("a memory line opens");
    let (_tx, requests) = std::sync::mpsc::channel();
    (Ctx::new(cfg, shared, requests, link), dev)
}

fn read_info02(id: u8) -> (Config, Want) {
    let want = Want {
        dev_id: id,
        index: InfoBlock::Info02.index(),
    };
    (Config::read(id, InfoBlock::Info02), want)
}

/// Reads one request frame off the device end (waits up to 2 s).
fn take_request(dev: &mut MemoryPort) {
    let mut buf = [0u8; 64];
    let mut got = 0;
    let until = Instant::now() + Duration::from_secs(2);
    while got < crate::protocol::FRAME_LEN && Instant::now() < until {
        got += dev
            .read_timeout(&mut buf, Duration::from_millis(50))
            .expect("the device end reads");
    }
    assert!(got >= crate::protocol::FRAME_LEN, "no request on the line");
}

#[test]
fn a_reply_that_woke_the_owner_does_not_raise_the_lag() {
    // Long after the spin: the owner is asleep in the port when it comes.
    let (mut ctx, mut dev) = ctx(|cfg| cfg.timing.reply_margin_us = 200_000);
    let (cmd, want) = read_info02(3);
    let device = std::thread::spawn(move || {
        take_request(&mut dev);
        std::thread::sleep(Duration::from_millis(20));
        let reply = Reply::new(3, ReplyBody::Unknown { index: want.index });
        dev.write_all(&reply.encode())
            .expect("the device end writes");
        dev
    });
    let got = ctx.exchange(cmd, want, false).expect("the line stays up");
    device.join().expect("the device thread ends");
    assert!(got.is_some(), "the reply came within its deadline");
    assert_eq!(
        ctx.reply_lag.lag(),
        Duration::ZERO,
        "a reply found on waking bounds its arrival from above: it may only lower the lag"
    );
}
