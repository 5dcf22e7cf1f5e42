//! `firmware = "auto"`: each online device is asked its revision once,
//! ahead of polls; devices the config names are told, never asked; an
//! unanswered probe is not a missed poll.

use super::*;
use crate::bus::firmware::{DeviceFirmware, FirmwareSetting, FirmwareSource};
use crate::protocol::params::Revision;

fn auto(ids: &[u8]) -> BusConfig {
    let mut cfg = config(ids);
    cfg.firmware = FirmwareSetting::Auto;
    cfg
}

fn firmware(b: &Bus, id: u8) -> Option<DeviceFirmware> {
    b.s.registry().get(id).and_then(|e| e.state.firmware)
}

#[test]
fn each_online_device_is_asked_once_and_probes_alternate_with_polls() {
    let mut b = Bus::with(auto(&[1, 2, 3]), &[1, 2]);
    assert_eq!(b.next(), Slot::Probe { dev_id: 1 });
    // Never two probes in a row: a bus of silent V2.0.1 devices still polls.
    let slots = b.run(6, &[3]);
    for pair in slots.windows(2) {
        assert!(
            !(matches!(pair[0], Slot::Probe { .. }) && matches!(pair[1], Slot::Probe { .. })),
            "{slots:?}"
        );
    }
    assert!(!polls(&slots).is_empty(), "{slots:?}");
    let detected = |revision| DeviceFirmware {
        revision,
        source: FirmwareSource::Detected,
        serial: None,
    };
    b.s.firmware_known(1, detected(Revision::V2_0_8));
    b.s.firmware_known(2, detected(Revision::V2_0_1));
    // Device 3 is offline: nothing to ask until it answers.
    let slots = b.run(20, &[3]);
    assert!(
        !slots.iter().any(|s| matches!(s, Slot::Probe { .. })),
        "{slots:?}"
    );
    assert_eq!(firmware(&b, 1).map(|f| f.revision), Some(Revision::V2_0_8));
    assert_eq!(firmware(&b, 2).map(|f| f.revision), Some(Revision::V2_0_1));
}

#[test]
fn silences_in_a_row_from_a_device_that_answers_polls_make_it_2_0_1() {
    let mut b = Bus::with(auto(&[1]), &[1]);
    // 1 + the default 2 retries.
    assert_eq!(b.s.probe_unanswered(1), None);
    assert_eq!(b.s.probe_unanswered(1), None);
    // A missed poll says the device may be gone: the count starts over.
    b.do_poll(1, InfoBlock::Info02, false);
    assert_eq!(b.s.probe_unanswered(1), None);
    assert_eq!(b.s.probe_unanswered(1), None);
    assert_eq!(b.s.probe_unanswered(1), Some(Revision::V2_0_1));
    let f = firmware(&b, 1).expect("known");
    assert_eq!(
        (f.revision, f.source),
        (Revision::V2_0_1, FirmwareSource::Detected)
    );
}

#[test]
fn devices_the_config_names_are_told_not_asked() {
    let mut cfg = auto(&[1, 2, 9]);
    cfg.firmware = FirmwareSetting::Fixed(Revision::V2_0_8);
    cfg.firmware_by_id
        .insert("9".into(), FirmwareSetting::Fixed(Revision::V2_0_1));
    let mut b = Bus::with(cfg, &[1, 2, 9]);
    let slots = b.run(10, &[]);
    assert!(
        !slots.iter().any(|s| matches!(s, Slot::Probe { .. })),
        "{slots:?}"
    );
    for (id, revision) in [
        (1, Revision::V2_0_8),
        (2, Revision::V2_0_8),
        (9, Revision::V2_0_1),
    ] {
        let f = firmware(&b, id).expect("told");
        assert_eq!((f.revision, f.source), (revision, FirmwareSource::Config));
    }
    // A mix with `auto` for some asks only those.
    let mut cfg = auto(&[1, 2]);
    cfg.firmware = FirmwareSetting::Fixed(Revision::V2_0_1);
    cfg.firmware_by_id.insert("2".into(), FirmwareSetting::Auto);
    let mut b = Bus::with(cfg, &[1, 2]);
    assert_eq!(b.next(), Slot::Probe { dev_id: 2 });
}

#[test]
fn an_unanswered_probe_is_not_a_missed_poll() {
    let mut b = Bus::with(auto(&[1]), &[1]);
    assert_eq!(b.next(), Slot::Probe { dev_id: 1 });
    for _ in 0..5 {
        let end = b.s.sent(b.now, 1);
        let window = b.s.reply_window(end);
        let want = Want {
            dev_id: 1,
            index: InfoBlock::Info07.index(),
        };
        b.s.unanswered(want, window.due, window.deadline);
        b.now = window.deadline;
    }
    let e = b.s.registry().get(1).expect("device 1");
    assert!(e.state.online);
    assert_eq!(e.state.missed_polls, 0);
}
