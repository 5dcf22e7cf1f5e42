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
