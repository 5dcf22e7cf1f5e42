//! The owner's reply wait against an in-memory line: what it learns of
//! the reply lag, and how soon it gives way to an e-stop.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::config::BusConfig;
use crate::bus::error::BusError;
use crate::bus::handle::{BusShared, BusSnapshot};
use crate::bus::link::Link;
use crate::bus::reply_lag::{Seen, MAX_LAG};
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
    (
        Ctx::new(cfg, shared, requests, link, Default::default()),
        dev,
    )
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

/// The quickest of `tries` exchanges of a silent device under a pending
/// e-stop, from the write to the owner giving way, and when each was
/// modelled to reach the end of its reply frame (`due`) and its grace.
fn quickest_give_way(ctx: &mut Ctx, tries: u32) -> Duration {
    ctx.shared.estop_generation.fetch_add(1, Ordering::SeqCst);
    let (cmd, want) = read_info02(3);
    // On a thread of its own set up as the owner's is: precise timers,
    // and the FIFO class where the host allows it (ignored where refused),
    // so a loaded test machine does not hold every wake-up past the bound.
    // Both end with the thread, not with the test harness's.
    std::thread::scope(|s| {
        s.spawn(|| {
            crate::rt::precise_timers();
            let _ = crate::rt::set_fifo(0, 10);
            (0..tries)
                .map(|_| {
                    let start = Instant::now();
                    let got = ctx.exchange(cmd, want, false);
                    assert!(
                        matches!(got, Err(BusError::Preempted)),
                        "the e-stop preempts the wait: {got:?}"
                    );
                    start.elapsed()
                })
                .min()
                .unwrap_or_default()
        })
        .join()
        .expect("the exchanges ran")
    })
}

#[test]
fn a_learnt_lag_does_not_hold_an_estop_past_the_grace() {
    let (mut ctx, _dev) = ctx(|_| {});
    // A path whose replies come late by the most the owner aims past.
    let t0 = Instant::now();
    for _ in 0..5_000 {
        ctx.reply_lag
            .observe(t0, t0 + Duration::from_millis(20), Seen::Watching);
    }
    assert_eq!(ctx.reply_lag.lag(), MAX_LAG);
    let frame = ctx.sched.clock().frame_time();
    // Request and reply frames, back to back (no turnaround): the reply is
    // modelled two frames after the write, its grace a frame later.
    let grace = frame * 3;
    // Asleep until the aim (less the most it wakes early by), the owner
    // could not give way before this.
    let asleep_until = frame * 2 + MAX_LAG - crate::rt::wake::MAX_LEAD;
    let quickest = quickest_give_way(&mut ctx, 50);
    assert!(
        quickest < asleep_until,
        "gave way {quickest:?} after the write at the quickest; the grace ends at {grace:?}"
    );
}

#[test]
fn a_long_spin_does_not_hold_an_estop_past_the_grace() {
    let (mut ctx, _dev) = ctx(|cfg| cfg.timing.reply_spin_us = 3_000);
    let frame = ctx.sched.clock().frame_time();
    let grace = frame * 3;
    let spun_until = frame * 2 + Duration::from_micros(3_000);
    let quickest = quickest_give_way(&mut ctx, 50);
    assert!(
        quickest < spun_until,
        "gave way {quickest:?} after the write at the quickest; the grace ends at {grace:?}"
    );
}

#[test]
fn a_request_frame_is_not_written_while_the_write_before_waits_to_be_seen_taken() {
    use crate::protocol::{Command, Control};
    use crate::transport::adapter::AdapterModel;

    let (mut ctx, mut dev) = ctx(|_| {});
    // The device end stands for an adapter whose count never falls.
    dev.reports_taken();
    ctx.sched.set_adapter(AdapterModel::Ch340);
    let t0 = Instant::now() - Duration::from_millis(100);
    for k in 0..40u64 {
        ctx.sched
            .arrival(t0 + Duration::from_micros(1_000 * k + 20));
    }
    assert!(ctx.sched.usb_clock_known());
    ctx.sched.set_port_confirms(true);
    // A setpoint frame (no reply: the kind a request lets out between its
    // frames, or an e-stop's disable before its read-back).
    ctx.send_without_reply(&[Command::Control(Control::disable(1))])
        .expect("written");
    assert!(ctx.sched.awaiting_confirmation());
    ctx.job_send(&[Command::Control(Control::disable(2))])
        .expect("written");
    let mut buf = [0u8; 64];
    let mut written = Vec::new();
    while written.len() < 2 {
        let n = dev
            .read_timeout(&mut buf, Duration::from_millis(100))
            .expect("the device end reads");
        assert!(n > 0, "both writes on the line");
        written.push(dev.take_written_at().expect("a dated write"));
    }
    // Untaken, the first was looked at each frame and given up on 4 ms
    // after its frame; only then did the request's frame go.
    let gap = written[1] - written[0];
    assert!(
        gap >= Duration::from_millis(3),
        "the request's frame went {gap:?} after a write still untaken"
    );
    assert_eq!(ctx.sched.take_confirm_counts(), (0, 1));
}
