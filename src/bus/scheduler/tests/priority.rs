//! Scheduler tests: priorities: e-stop, requests, scan.

use super::*;

#[test]
fn estop_beats_a_queued_request_and_pending_setpoints() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    bus.request = true;
    bus.estop = 1;
    assert_eq!(bus.next(), Slot::EStop { generation: 1 });
    assert!(!bus.s.estop_pending(1), "served once");
    assert_eq!(bus.next(), Slot::Request);
}

#[test]
fn estop_waits_only_for_the_line_to_free() {
    let mut bus = Bus::new(&[1], &[1]);
    let end = bus.s.sent(bus.now, 1);
    bus.estop = 1;
    let write_at = bus.s.clock().write_at();
    assert_eq!(write_at, end - Duration::from_micros(300));
    assert_eq!(bus.next(), Slot::Listen { until: write_at });
    bus.now = write_at;
    assert_eq!(bus.next(), Slot::EStop { generation: 1 });
}

#[test]
fn estop_is_served_on_a_down_bus_too() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.link_lost(bus.now);
    bus.estop = 3;
    assert_eq!(bus.next(), Slot::EStop { generation: 3 });
    assert!(matches!(bus.next(), Slot::Reopen { .. }));
}

#[test]
fn a_queued_request_beats_setpoints_and_polls() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.set([1], 500);
    bus.request = true;
    assert_eq!(bus.next(), Slot::Request);
}

#[test]
fn the_startup_scan_runs_until_done_after_requests() {
    let mut bus = Bus::with(config(&[]), &[]);
    assert_eq!(bus.next(), Slot::Scan);
    bus.request = true;
    assert_eq!(bus.next(), Slot::Request, "a request goes before the scan");
    bus.request = false;
    assert_eq!(bus.next(), Slot::Scan, "not done: asked again");
    bus.s.scan_done();
    assert!(matches!(bus.next(), Slot::Listen { .. }));
}

/// A scheduler whose devices were running before it started.
fn found_running(policy: crate::bus::config::StartPolicy) -> Bus {
    let mut cfg = config(&[1, 2]);
    cfg.on_start = policy;
    let mut bus = Bus::with(cfg, &[]);
    bus.s.unsolicited(&info01(1, fsm::RUN), bus.now);
    bus.s.unsolicited(&info01(2, fsm::READY), bus.now);
    bus
}

#[test]
fn a_joint_found_enabled_is_released_first_with_on_start_disable() {
    let mut bus = found_running(crate::bus::config::StartPolicy::Disable);
    let events: Vec<_> = bus.s.drain_events().collect();
    assert!(events.iter().any(|e| matches!(
        e,
        BusEvent::FoundEnabled {
            dev_id: 1,
            on_start: "disable",
            ..
        }
    )));
    bus.set([2], 500);
    bus.request = true;
    bus.estop = 1;
    assert_eq!(
        bus.next(),
        Slot::EStop { generation: 1 },
        "an e-stop still first"
    );
    assert_eq!(bus.next(), Slot::Release { ids: vec![1] });
    assert_eq!(bus.next(), Slot::Request, "released once");
    assert!(!bus.s.registry().get(1).unwrap().state.target_known);
    assert!(bus.s.registry().get(2).unwrap().state.target_known);
}

#[test]
fn a_joint_found_enabled_is_left_alone_with_on_start_keep() {
    let mut bus = found_running(crate::bus::config::StartPolicy::Keep);
    let events: Vec<_> = bus.s.drain_events().collect();
    assert!(events.iter().any(|e| matches!(
        e,
        BusEvent::FoundEnabled {
            dev_id: 1,
            on_start: "keep",
            ..
        }
    )));
    bus.request = true;
    assert_eq!(bus.next(), Slot::Request);
    assert!(!bus.s.registry().get(1).unwrap().state.target_known);
    // Heard running again: still nothing to release, still unknown.
    bus.s.unsolicited(&info01(1, fsm::RUN), bus.now);
    bus.request = false;
    assert!(!matches!(bus.next(), Slot::Release { .. }));
    assert!(!bus.s.registry().get(1).unwrap().state.target_known);
}
