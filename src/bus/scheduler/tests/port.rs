//! Scheduler tests: the port: opening, quiet spell, loss, backoff.

use super::*;
use crate::transport::adapter::AdapterModel;

#[test]
fn a_new_bus_opens_its_port_at_once() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    let store = SetpointStore::default();
    let work = Work {
        estop_generation: 0,
        request_queued: true,
        setpoints: &store,
    };
    assert_eq!(s.next(t0, &work), Slot::Reopen { at: t0 });
}

#[test]
fn a_freshly_opened_port_is_only_listened_to() {
    let mut bus = Bus::new(&[1], &[1]);
    let opened = bus.now - LISTEN_ON_OPEN;
    bus.now = opened + Duration::from_millis(5);
    bus.request = true;
    assert_eq!(
        bus.next(),
        Slot::Listen {
            until: opened + LISTEN_ON_OPEN
        }
    );
}

/// Behind an FTDI chip with a 16 ms timer, announcements reach the host up
/// to 17 ms after they left the wire: the port is listened to that much
/// longer before a device is polled.
#[test]
fn behind_an_adapter_the_quiet_spell_waits_out_its_hold() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    s.set_adapter(AdapterModel::Ftdi { latency_ms: 16 });
    s.link_up(t0);
    let store = SetpointStore::default();
    let work = Work {
        estop_generation: 0,
        request_queued: true,
        setpoints: &store,
    };
    let hold = Duration::from_millis(17);
    assert_eq!(
        s.next(t0 + LISTEN_ON_OPEN, &work),
        Slot::Listen {
            until: t0 + LISTEN_ON_OPEN + hold
        }
    );
}

#[test]
fn reopen_backoff_doubles_up_to_its_cap() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    let waits: Vec<u64> = (0..8)
        .map(|_| s.open_failed(t0).as_millis() as u64)
        .collect();
    assert_eq!(waits, vec![20, 40, 80, 160, 320, 640, 1000, 1000]);
    let store = SetpointStore::default();
    let work = Work {
        estop_generation: 0,
        request_queued: false,
        setpoints: &store,
    };
    assert_eq!(
        s.next(t0, &work),
        Slot::Reopen {
            at: t0 + BACKOFF_MAX
        }
    );
}

#[test]
fn a_successful_open_resets_the_backoff() {
    let t0 = Instant::now();
    let mut s = Scheduler::new(&config(&[1]), t0);
    s.open_failed(t0);
    s.open_failed(t0);
    assert!(!s.link_up(t0), "first open is no reconnect");
    assert_eq!(s.link_lost(t0), BACKOFF_FIRST);
    assert_eq!(s.open_failed(t0), BACKOFF_FIRST);
    assert!(s.link_up(t0), "second open is a reconnect");
}

#[test]
fn a_lost_link_takes_every_device_offline_and_drops_pending() {
    let mut bus = Bus::new(&[1, 2], &[1, 2]);
    bus.set([1, 2], 500);
    bus.s.prepare(bus.now, &bus.store);
    assert!(!bus.s.pending().is_empty());
    let lost_at = bus.now;
    assert_eq!(bus.s.link_lost(lost_at), BACKOFF_FIRST);
    assert!(bus.s.registry().online_ids().is_empty());
    assert!(bus.s.pending().is_empty());
    assert_eq!(bus.s.drain_events().count(), 2, "two DeviceOffline events");
    assert_eq!(
        bus.next(),
        Slot::Reopen {
            at: lost_at + BACKOFF_FIRST
        }
    );
}

#[test]
fn setpoints_written_while_down_are_stale_when_it_comes_back() {
    let mut bus = Bus::new(&[1], &[1]);
    bus.s.link_lost(bus.now);
    bus.set([1], 700);
    assert!(matches!(bus.next(), Slot::Reopen { .. }));
    bus.s.link_up(bus.now);
    bus.s.unsolicited(&info01(1, fsm::RUN), bus.now);
    bus.now += LISTEN_ON_OPEN;
    let slots = bus.run(20, &[]);
    assert!(controls(&slots).is_empty(), "{slots:?}");
}
