//! Scheduler tests: one-shot requests: interleaving, exclusive phase, preemption.

use super::*;

#[test]
fn setpoints_interleave_at_most_twice_between_job_frames() {
    let mut bus = Bus::new(&[1, 2, 3, 9], &[1, 2, 3, 9]);
    bus.s.job_start();
    assert_eq!(bus.s.interleave(bus.now, &bus.store, 0), None);
    bus.set([1, 2, 3, 9], 500);
    assert_eq!(
        bus.s.interleave(bus.now, &bus.store, 0),
        None,
        "not before the request's first frame"
    );
    bus.s.job_frame(0).ok();
    let mut between = 0;
    while let Some(frame) = bus.s.interleave(bus.now, &bus.store, 0) {
        bus.send_control(&frame);
        between += 1;
    }
    assert_eq!(between, MAX_INTERLEAVED);
    bus.s.job_frame(0).ok();
    assert!(
        bus.s.interleave(bus.now, &bus.store, 0).is_some(),
        "again after the next"
    );
}

#[test]
fn nothing_interleaves_in_the_exclusive_phase() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.job_start();
    bus.s.job_frame(0).ok();
    bus.set([1], 500);
    bus.s.set_exclusive(true);
    assert_eq!(bus.s.interleave(bus.now, &bus.store, 0), None);
    bus.s.set_exclusive(false);
    assert!(bus.s.interleave(bus.now, &bus.store, 0).is_some());
}

#[test]
fn an_estop_preempts_a_job_except_in_its_exclusive_phase() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.job_start();
    assert_eq!(bus.s.job_frame(0), Ok(()));
    bus.set([1], 500);
    assert_eq!(
        bus.s.interleave(bus.now, &bus.store, 1),
        None,
        "no setpoint before an e-stop"
    );
    bus.s.set_exclusive(true);
    assert_eq!(
        bus.s.job_frame(1),
        Ok(()),
        "the baud switch runs to its end"
    );
    bus.s.set_exclusive(false);
    assert_eq!(bus.s.job_frame(1), Err(Preempted));
}
