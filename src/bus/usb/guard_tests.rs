use super::*;

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

#[test]
fn garbled_bytes_step_up_once_per_settle_and_never_past_lockstep() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    assert_eq!(g.garbled_total(0, t0 + ms(100)), None);
    let up = g.garbled_total(20, t0 + ms(100)).expect("a step up");
    assert_eq!(
        (up.from, up.to),
        (PipelineMode::Pipelined, PipelineMode::Guarded)
    );
    assert!(up.reason.contains("20 garbled"), "{}", up.reason);
    // The same collision's aftermath, a moment later: no second step.
    assert_eq!(g.garbled_total(40, t0 + ms(110)), None);
    assert_eq!(g.mode(), PipelineMode::Guarded);
    // Behind a latency timer a second incident widens the guard...
    let up = g.garbled_total(41, t0 + ms(200)).expect("a second step");
    assert_eq!(
        (up.from, up.to),
        (PipelineMode::Guarded, PipelineMode::Guarded)
    );
    assert!(up.backed_off);
    assert!(up.reason.contains("guard widened to 2500"), "{}", up.reason);
    assert_eq!(g.reach(), WIDE_GUARDED_REACH);
    assert!(g.blind());
    // ... and a third goes to lockstep, the top.
    let up = g.garbled_total(42, t0 + ms(300)).expect("a third step");
    assert_eq!(up.to, PipelineMode::Lockstep);
    assert!(!g.blind());
    assert_eq!(g.garbled_total(60, t0 + ms(500)), None);
    assert_eq!(g.mode(), PipelineMode::Lockstep);
}

#[test]
fn lockstep_steps_down_through_the_widened_guard_then_the_narrow_one() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    for (k, total) in [1, 2, 3].into_iter().enumerate() {
        let at = t0 + ms(100 * (k as u64 + 1));
        assert!(g.garbled_total(total, at).is_some_and(|c| c.backed_off));
    }
    assert_eq!(g.mode(), PipelineMode::Lockstep);
    let steps: Vec<(PipelineMode, Duration, bool)> = [1400, 2500, 3600]
        .into_iter()
        .map(|t| {
            let c = g.tick(t0 + ms(t)).expect("a step down");
            (c.to, g.reach(), c.backed_off)
        })
        .collect();
    assert_eq!(
        steps,
        [
            (PipelineMode::Guarded, WIDE_GUARDED_REACH, false),
            (PipelineMode::Guarded, GUARDED_REACH, false),
            (PipelineMode::Pipelined, PIPELINED_REACH, false),
        ]
    );
    assert_eq!(
        g.view(Duration::from_millis(1), t0 + ms(3600)).recoveries,
        3
    );
}

#[test]
fn an_adapter_whose_replies_come_at_the_next_frame_skips_guarded_both_ways() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), true, t0);
    let up = g.garbled_total(20, t0 + ms(100)).expect("a step up");
    assert_eq!(
        (up.from, up.to),
        (PipelineMode::Pipelined, PipelineMode::Lockstep)
    );
    assert_eq!(g.tick(t0 + ms(600)), None);
    let down = g.tick(t0 + ms(1200)).expect("a step down");
    assert_eq!(
        (down.from, down.to),
        (PipelineMode::Lockstep, PipelineMode::Pipelined)
    );
    // Named again behind a latency timer: guarded is back in the ladder.
    g.set_replies_next_frame(false);
    let up = g.garbled_total(40, t0 + ms(1300)).expect("a step up");
    assert_eq!(up.to, PipelineMode::Guarded);
}

#[test]
fn guarded_named_again_without_a_latency_timer_goes_to_lockstep_not_widened() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    g.garbled_total(1, t0 + ms(100)).expect("up");
    assert_eq!(g.mode(), PipelineMode::Guarded);
    // A CH340 now: lockstep costs what guarded does, a widened guard more.
    g.set_replies_next_frame(true);
    let up = g.garbled_total(2, t0 + ms(200)).expect("up");
    assert_eq!(
        (up.from, up.to, g.reach()),
        (
            PipelineMode::Guarded,
            PipelineMode::Lockstep,
            LOCKSTEP_REACH
        ),
        "{}",
        up.reason
    );
}

#[test]
fn a_device_gone_is_not_evidence_but_a_lost_reply_is() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    // Device 3 stops answering: misses, and never answers again.
    for k in 1..=5 {
        g.reply_missing(3, t0 + ms(100 * k));
        assert_eq!(g.answered(4, t0 + ms(100 * k + 10)), None);
    }
    assert_eq!(g.mode(), PipelineMode::Pipelined);
    // Device 5 misses one reply and answers the next poll.
    g.reply_missing(5, t0 + ms(700));
    let up = g.answered(5, t0 + ms(730)).expect("evidence");
    assert!(up.reason.contains("device 5"), "{}", up.reason);
    // A miss of a transfer written before the step, confirmed later: no second step.
    g.reply_missing(6, t0 + ms(740));
    assert_eq!(g.answered(6, t0 + ms(900)), None);
    assert_eq!(g.mode(), PipelineMode::Guarded);
    // An answer long after the miss says nothing.
    let mut g = UsbGuard::new(ms(1000), false, t0);
    g.reply_missing(5, t0 + ms(100));
    assert_eq!(g.answered(5, t0 + ms(1200)), None);
}

#[test]
fn steps_down_after_a_clean_recovery_time_and_doubles_it_on_a_relapse() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    g.garbled_total(1, t0 + ms(100)).expect("up");
    assert_eq!(g.tick(t0 + ms(1000)), None);
    let down = g.tick(t0 + ms(1100)).expect("down after 1 s clean");
    assert_eq!(down.to, PipelineMode::Pipelined);
    assert!(down.reason.starts_with("recovered"), "{}", down.reason);
    // Relapse soon after: up again, and the next recovery takes twice as long.
    g.garbled_total(2, t0 + ms(1500)).expect("up again");
    assert_eq!(g.tick(t0 + ms(3400)), None);
    assert!(g.tick(t0 + ms(3600)).is_some());
    assert_eq!(
        g.view(Duration::from_millis(1), t0 + ms(3600)).recoveries,
        2
    );
    // Backed off, a write seen late restarts the clean time.
    g.garbled_total(3, t0 + ms(4000)).expect("up");
    g.write_seen_late(t0 + ms(5500));
    assert_eq!(g.tick(t0 + ms(6500)), None);
    assert_eq!(
        g.view(Duration::from_millis(1), t0 + ms(6500)).late_writes,
        1
    );
    // At the bottom nothing steps down.
    assert!(g.tick(t0 + ms(100_000)).is_some());
    assert_eq!(g.mode(), PipelineMode::Pipelined);
    assert_eq!(g.tick(t0 + ms(200_000)), None);
}

#[test]
fn three_late_sentinels_of_32_back_off_and_a_late_one_keeps_a_backed_off_mode() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    // Two late ones among many on time: a host that read late twice.
    for k in 0..100 {
        assert_eq!(g.sentinel(k == 10 || k == 50, t0 + ms(100 + k)), None);
    }
    assert_eq!(g.mode(), PipelineMode::Pipelined);
    // Three within 32: evidence, and the same step as a collision's.
    assert_eq!(g.sentinel(true, t0 + ms(300)), None);
    assert_eq!(g.sentinel(false, t0 + ms(301)), None);
    assert_eq!(g.sentinel(true, t0 + ms(302)), None);
    let up = g.sentinel(true, t0 + ms(303)).expect("evidence");
    assert_eq!(up.to, PipelineMode::Guarded);
    assert!(
        up.reason.contains("3 of the last 32 sentinel"),
        "{}",
        up.reason
    );
    // Backed off, one late sentinel alone leaves the clean time running...
    assert_eq!(g.sentinel(true, t0 + ms(350)), None);
    assert_eq!(g.clean_from, t0 + ms(303));
    // ... three do not step further but restart it.
    for k in 0..10 {
        assert_eq!(g.sentinel(true, t0 + ms(400 + 50 * k)), None);
    }
    assert_eq!(g.mode(), PipelineMode::Guarded);
    assert_eq!(g.tick(t0 + ms(1500)), None);
    assert!(g.tick(t0 + ms(1900)).is_some());
    let v = g.view(Duration::from_millis(1), t0 + ms(1900));
    assert_eq!((v.sentinels, v.sentinels_late, v.late_writes), (115, 16, 0));
}

#[test]
fn the_factor_is_bounded() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(10), false, t0);
    let mut t = t0;
    for total in 1..200 {
        t += ms(60);
        g.garbled_total(total, t);
        t += g.recover_after();
        g.tick(t);
    }
    assert!(g.recover_after() <= ms(10) * MAX_RECOVER_FACTOR);
}

#[test]
fn the_view_says_mode_guard_reason_and_rate() {
    let t0 = Instant::now();
    let mut g = UsbGuard::new(ms(1000), false, t0);
    let v = g.view(Duration::from_millis(1), t0);
    assert_eq!(
        (v.mode, v.guard_us, v.lead_us),
        (PipelineMode::Pipelined, 200, 800)
    );
    assert_eq!(v.reason, "start");
    g.garbled_total(3, t0 + ms(100));
    let v = g.view(Duration::from_millis(1), t0 + ms(100));
    assert_eq!(
        (v.mode, v.guard_us, v.lead_us),
        (PipelineMode::Guarded, 1500, 900)
    );
    assert!((v.incidents_per_s - 0.1).abs() < 1e-9);
    assert_eq!(v.backoffs, 1);
}
