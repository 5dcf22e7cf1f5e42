use super::*;
use crate::bus::packets::PacketMark;
use crate::bus::usb::frame_clock::PHASE_SAMPLES;
use crate::bus::wire::{ReplyWindow, Want};

fn us(n: u64) -> Duration {
    Duration::from_micros(n)
}

/// A frame clock with boundaries at `t0 + 300 µs + k ms`, learnt from
/// arrivals `lateness` after boundaries.
fn pipeline(adapter: AdapterModel) -> UsbPipeline {
    UsbPipeline::for_adapter(adapter, Duration::from_secs(10), Instant::now())
        .expect("a USB adapter")
}

/// A full-speed FTDI chip with a 1 ms timer: 1 ms frames, sentinels.
const FTDI_1: AdapterModel = AdapterModel::Ftdi { latency_ms: 1 };

fn learnt(t0: Instant, lateness: &[u64]) -> UsbPipeline {
    let mut p = pipeline(FTDI_1);
    for (k, late) in lateness.iter().enumerate() {
        p.arrival(t0 + us(300 + 1000 * (k as u64 + 1) + late));
    }
    p
}

#[test]
fn the_boundary_is_the_start_of_the_arrivals_cluster() {
    let t0 = Instant::now();
    let mut late = vec![40, 12, 25, 900, 30, 18, 14, 60];
    late.extend([20; PHASE_SAMPLES - 8]);
    let p = learnt(t0, &late);
    assert!(p.active());
    // The 900 µs outlier (a stalled thread) is not taken for early.
    // The dense cluster's start (a few µs after the earliest read at 312 µs).
    let b = p.phase.boundary_after(t0 + us(10_000)) - t0;
    assert!(b >= us(10_312) && b <= us(10_320), "{b:?}");
}

#[test]
fn a_trusted_estimate_moves_at_most_5_us_per_arrival() {
    let t0 = Instant::now();
    let mut p = learnt(t0, &[0; PHASE_SAMPLES]);
    let before = p.phase.boundary_after(t0 + us(100_000));
    // A burst of reads 40 µs late (a busy host) would move the raw
    // estimate by 40 µs at once.
    for k in 0..PHASE_SAMPLES as u64 {
        p.arrival(t0 + us(300 + 1000 * (40 + k) + 40));
        let now = p.phase.boundary_after(t0 + us(100_000));
        assert!(now - before <= us(5 * (k + 1)), "{:?}", now - before);
    }
    assert!(p.active());
}

#[test]
fn not_active_before_enough_arrivals_nor_while_they_disagree() {
    let t0 = Instant::now();
    assert!(!learnt(t0, &[10; PHASE_SAMPLES - 1]).active());
    assert!(learnt(t0, &[10; PHASE_SAMPLES]).active());
    // Arrivals all over the period: a host too busy to read them when
    // they come shows no boundary.
    let spread: Vec<u64> = (0..PHASE_SAMPLES as u64).map(|k| k * 31 % 1000).collect();
    assert!(!learnt(t0, &spread).active());
}

/// Every sighting of a boundary is late by the host's wake-up, so the
/// learnt clock runs that much behind the adapter's: a write is taken
/// to make a boundary only with the reach and that lag to spare, and a
/// sentinel is aimed earlier by it and by the host's lateness to hand
/// it over.
#[test]
fn the_hosts_arrival_lag_is_spared_before_a_boundary() {
    let t0 = Instant::now();
    let mut p = learnt(t0, &[0; PHASE_SAMPLES]);
    // Pipelined: a 200 µs reach. Handed 230 µs before the 10.3 ms
    // boundary, a write makes it with no lag...
    let handed = t0 + us(10_070);
    assert_eq!(
        p.released(handed),
        Released {
            at: t0 + us(10_300),
            ambiguous: false
        }
    );
    // ... but sighted 40 µs late, the boundary may be at 10.26 ms,
    // and a write 190 µs late would miss it: held for the next.
    p.set_arrival_lag(us(40));
    assert_eq!(
        p.released(handed),
        Released {
            at: t0 + us(11_300),
            ambiguous: true
        }
    );
    // Early in the frame, as writes are aimed, nothing changes.
    assert_eq!(p.released(t0 + us(9_500)).at, t0 + us(10_300));
    // A sentinel due: a tenth of a frame before the boundary, which may
    // be the lag earlier, and asked the lag again earlier still (the
    // host wakes that late to hand it over).
    p.since_sentinel = SENTINEL_EVERY;
    let free = t0 + us(10_100);
    assert_eq!(p.sentinel_wait(free, t0 + us(9_000)), Some(t0 + us(10_120)));
}

#[test]
fn a_write_is_aimed_early_in_the_frame_before_its_boundary() {
    let t0 = Instant::now();
    let p = learnt(t0, &[0; PHASE_SAMPLES]);
    // Wire free at 10.1 ms: the first boundary after it plus the
    // guard is 10.3 ms; write 0.8 of a frame before.
    let free = t0 + us(10_100);
    assert_eq!(p.write_at(free, t0 + us(9_000)), t0 + us(9_500));
    // Late, but still before the boundary: write now (the wire will
    // be held for the later frame, see `released`).
    assert_eq!(p.write_at(free, t0 + us(10_260)), t0 + us(9_500));
    // Too close to it: the next one.
    assert_eq!(p.write_at(free, t0 + us(10_295)), t0 + us(10_500));
}

#[test]
fn a_write_close_to_a_boundary_holds_the_wire_for_the_later_one() {
    let t0 = Instant::now();
    let p = learnt(t0, &[0; PHASE_SAMPLES]);
    let clear = p.released(t0 + us(9_800));
    assert_eq!(clear.at, t0 + us(10_300));
    assert!(!clear.ambiguous);
    let close = p.released(t0 + us(10_150));
    assert_eq!(close.at, t0 + us(11_300));
    assert!(close.ambiguous);
}

/// The poll the sentinel tests write.
const SENTINEL_POLL: Want = Want {
    dev_id: 1,
    index: 2,
};

/// A reply window due `due_us` after `t0`, given up 10 ms later.
fn window_at(t0: Instant, due_us: u64) -> ReplyWindow {
    ReplyWindow {
        due: t0 + us(due_us),
        deadline: t0 + us(due_us + 10_000),
    }
}

/// Sentinels judged, and late, as the bus view counts them.
fn sentinel_counts(p: &mut UsbPipeline, t0: Instant) -> (u64, u64) {
    let v = p.guard_mut().view(Duration::from_millis(1), t0);
    (v.sentinels, v.sentinels_late)
}

#[test]
fn a_sentinel_reply_a_frame_late_shows_its_write_late() {
    let t0 = Instant::now();
    let mut p = learnt(t0, &[0; PHASE_SAMPLES]);
    let (want, window) = (SENTINEL_POLL, window_at(t0, 20_000));
    let view = |p: &mut UsbPipeline| sentinel_counts(p, t0);
    // Written 100 µs before the 10.3 ms boundary: held for the next.
    let handed = t0 + us(10_200);
    p.arm_sentinel();
    assert_eq!(p.released(handed).at, t0 + us(11_300));
    assert!(!p.released(handed).ambiguous);
    // Its reply ends 1.7 ms after the boundary it made (12.0 ms), is
    // modelled from the later one (13.0 ms), and reaches the host at
    // the boundary after its end: 12.3 ms if on time.
    p.track(
        want,
        window,
        (handed, 0),
        t0 + us(13_000),
        (t0 + us(13_000), us(400)),
    );
    let on_time = p.take(want, 0, 0).expect("tracked");
    assert!(on_time.sentinel);
    assert_eq!(on_time.on_time, Some(t0 + us(12_300)));
    assert_eq!(p.answered(&on_time, t0 + us(12_330)), None);
    assert_eq!(view(&mut p), (1, 0));
    assert_eq!(p.answered(&on_time, t0 + us(13_330)), None);
    assert_eq!(view(&mut p), (2, 1));
    // Read 1.6 ms after on time: the host's lateness, not judged.
    assert_eq!(p.answered(&on_time, t0 + us(13_900)), None);
    assert_eq!(view(&mut p), (2, 1));
    // Handed 30 µs before its boundary (the host woke late): not judged.
    p.arm_sentinel();
    let end = t0 + us(13_000);
    p.track(want, window, (t0 + us(10_270), 0), end, (end, us(400)));
    let close = p.take(want, 0, 0).expect("tracked");
    assert!(!close.sentinel);
    assert_eq!(p.answered(&close, t0 + us(13_330)), None);
    assert_eq!(view(&mut p), (2, 1));
    // Nor is the next write armed.
    assert_eq!(p.released(t0 + us(9_800)).at, t0 + us(10_300));
    // Handed 100 µs before it by a host that sees replies 50 µs late:
    // 50 µs to spare at most, not judged either.
    p.set_arrival_lag(us(50));
    p.arm_sentinel();
    p.track(want, window, (t0 + us(10_200), 0), end, (end, us(400)));
    assert!(!p.take(want, 0, 0).expect("tracked").sentinel);
}

#[test]
fn behind_a_long_timer_a_sentinel_is_dated_by_the_packet_its_reply_ends() {
    let t0 = Instant::now();
    let mut p = learnt(t0, &[0; PHASE_SAMPLES]);
    p.set_adapter(AdapterModel::Ftdi { latency_ms: 16 });
    let (want, window) = (SENTINEL_POLL, window_at(t0, 30_000));
    let view = |p: &mut UsbPipeline| sentinel_counts(p, t0);
    // As above: made the 10.3 ms boundary, its reply ends at 12.0 ms on
    // time (13.0 ms as modelled from the later boundary), and a 16 ms
    // timer holds it after that.
    p.arm_sentinel();
    let wire_end = t0 + us(13_000);
    p.track(
        want,
        window,
        (t0 + us(10_200), 0),
        wire_end + us(16_000),
        (wire_end, us(400)),
    );
    let s = p.take(want, 0, 0).expect("tracked");
    assert!(s.sentinel);
    assert_eq!(s.on_time, None, "behind the timer its arrival says nothing");
    assert_eq!(p.answered(&s, t0 + us(12_330)), None);
    assert_eq!(view(&mut p), (0, 0));
    // Its 2nd byte ended a full packet: in at 12.0 ms less 18 bytes of
    // 20 µs (11.64 ms) on time, the packet at the host at 12.3 ms.
    let mark = |at: u64| PacketMark {
        byte: 2,
        read_at: t0 + us(at),
    };
    assert_eq!(p.answered_packet(&s, mark(12_340)), None);
    assert_eq!(view(&mut p), (1, 0));
    // Read a frame later: the write slipped a frame.
    assert_eq!(p.answered_packet(&s, mark(13_340)), None);
    assert_eq!(view(&mut p), (2, 1));
    // Read 1.6 ms after on time: the host's lateness, not judged.
    assert_eq!(p.answered_packet(&s, mark(13_900)), None);
    assert_eq!(view(&mut p), (2, 1));
}

#[test]
fn a_reply_two_frames_late_is_a_slip_only_where_the_widened_guard_holds_for_it() {
    let t0 = Instant::now();
    let mut p = learnt(t0, &[0; PHASE_SAMPLES]);
    let want = Want {
        dev_id: 4,
        index: 1,
    };
    let late_writes = |p: &mut UsbPipeline| p.guard_mut().view(us(1_000), t0).late_writes;
    // A poll, and when its reply reads `frames` frames after on time
    // (read promptly: 30 µs after that boundary).
    let poll = |p: &mut UsbPipeline| {
        let end = t0 + us(13_000);
        p.track(
            want,
            window_at(t0, 20_000),
            (t0 + us(10_200), 0),
            end,
            (end, us(400)),
        );
        let polled = p.take(want, 0, 0).expect("tracked");
        let on_time = polled.on_time.expect("judged by its arrival");
        (polled, move |frames: u64| on_time + us(30 + 1_000 * frames))
    };
    p.guard_mut()
        .garbled_total(1, t0 + us(100_000))
        .expect("guarded");
    let (narrow, read) = poll(&mut p);
    assert_eq!(p.answered(&narrow, read(2)), None);
    assert_eq!(
        late_writes(&mut p),
        0,
        "a 1.5 ms guard: another poll's reply"
    );
    assert_eq!(p.answered(&narrow, read(1)), None);
    assert_eq!(late_writes(&mut p), 1, "a frame late counts");
    let wide = p
        .guard_mut()
        .garbled_total(2, t0 + us(200_000))
        .expect("widened");
    assert_eq!(
        (wide.to, p.guard().reach()),
        (PipelineMode::Guarded, us(2_500))
    );
    let (held, read) = poll(&mut p);
    assert_eq!(p.answered(&held, read(2)), None);
    assert_eq!(late_writes(&mut p), 2, "the widened guard held it");
    assert_eq!(p.answered(&held, read(3)), None);
    assert_eq!(
        late_writes(&mut p),
        2,
        "three frames late is no slip there either"
    );
}

#[test]
fn without_a_known_clock_a_write_may_leave_a_period_and_its_reach_later() {
    let t0 = Instant::now();
    let p = pipeline(FTDI_1);
    assert_eq!(p.latest_release(t0).at, t0 + us(1_200));
    let hs = pipeline(AdapterModel::Ft232h { latency_ms: 1 });
    assert_eq!(hs.latest_release(t0).at, t0 + us(250));
}

/// What a poll of device 4's INFO_01 written at `t0` wants, and when.
fn info01_poll_of_device_4(t0: Instant) -> (Want, ReplyWindow) {
    let want = Want {
        dev_id: 4,
        index: 1,
    };
    let window = ReplyWindow {
        due: t0,
        deadline: t0 + Duration::from_millis(5),
    };
    (want, window)
}

#[test]
fn of_replies_read_together_only_the_last_answer_the_polls_in_flight() {
    let t0 = Instant::now();
    let mut p = pipeline(FTDI_1);
    let (want, window) = info01_poll_of_device_4(t0);
    p.track(want, window, (t0, 0), t0, (t0, us(400)));
    // An announcement held with the reply: the earlier of the two is none.
    assert_eq!(p.take(want, 1, 0), None);
    assert_eq!(p.in_flight(), 1);
    assert!(p.take(want, 0, 0).is_some());
    // Two polls of one block in flight, both replies in hand: both answer.
    p.track(want, window, (t0, 0), t0, (t0, us(400)));
    p.track(want, window, (t0, 0), t0, (t0, us(400)));
    assert!(p.take(want, 1, 0).is_some());
    assert!(p.take(want, 0, 0).is_some());
    assert_eq!(p.in_flight(), 0);
}

/// A power-up announcement whose first bytes were read before a poll of
/// its device was written, its end held by the adapter's timer until
/// after: it answers no poll, in whatever read its end came.
#[test]
fn a_reply_begun_before_the_polls_write_answers_none() {
    let t0 = Instant::now();
    let mut p = pipeline(FTDI_1);
    let (want, window) = info01_poll_of_device_4(t0);
    // 62 bytes read before the write: the announcement began at byte 60.
    p.track(want, window, (t0, 62), t0, (t0, us(400)));
    assert_eq!(p.take(want, 0, 60), None);
    assert_eq!(p.in_flight(), 1);
    // The reply, begun at byte 80.
    assert!(p.take(want, 0, 80).is_some());
    // Of two polls in flight, a reply begun between their writes answers
    // the first.
    p.track(want, window, (t0, 100), t0, (t0, us(400)));
    p.track(want, window, (t0, 140), t0, (t0, us(400)));
    assert_eq!(p.take(want, 0, 120).map(|i| i.read_before), Some(100));
    assert_eq!(p.take(want, 0, 160).map(|i| i.read_before), Some(140));
}

#[test]
fn replies_are_matched_oldest_first_and_expire_by_deadline() {
    let t0 = Instant::now();
    let mut p = pipeline(FTDI_1);
    let want = |dev_id| Want { dev_id, index: 1 };
    let window = |ms| ReplyWindow {
        due: t0 + Duration::from_millis(ms),
        deadline: t0 + Duration::from_millis(ms + 5),
    };
    p.track(want(1), window(1), (t0, 0), t0, (t0, us(400)));
    p.track(want(2), window(2), (t0, 0), t0, (t0, us(400)));
    p.track(want(1), window(3), (t0, 0), t0, (t0, us(400)));
    assert_eq!(p.take(want(1), 0, 0).map(|i| i.window), Some(window(1)));
    assert_eq!(p.next_deadline(), Some(t0 + Duration::from_millis(7)));
    let gone = p.expired(t0 + Duration::from_millis(7));
    assert_eq!(gone.len(), 1);
    assert_eq!(gone[0].want, want(2));
    assert_eq!(p.in_flight(), 1);
    p.reset();
    assert_eq!(p.in_flight(), 0);
    assert!(!p.active());
}
