//! A bus-wide config PATCH writes the online devices the daemon manages,
//! never an offline one and an unmanaged one only when asked
//! (`include_unmanaged=true`); the frame to 0xFF is used only when no
//! device would hear it unasked; the answer names every device written and
//! every device skipped, with why.

mod support;

use std::collections::BTreeMap;

use jointd::control::Options;
use jointd::protocol::command::index;
use jointd::protocol::{Command, Config, Frame, ALL_DEVICES};
use jointd::sim::Fault;
use serde_json::{json, Value};
use support::sim_bus::{start_with, SimBus};

/// Config frames the host sent for parameter `idx`: (addressed id, raw).
fn config_writes(bus: &SimBus, idx: u8) -> Vec<(u8, u16)> {
    bus.sim
        .frame_log()
        .iter()
        .filter(|f| f.from_host)
        .filter_map(
            |f| match Frame::decode(&f.bytes).map(|fr| Command::from_frame(&fr)) {
                Ok(Ok(Command::Config(Config { dev_id, param }))) => {
                    let (i, v) = param.index_value();
                    (i == idx).then_some((dev_id, v))
                }
                _ => None,
            },
        )
        .collect()
}

fn max_cur(bus: &SimBus, id: u8) -> u16 {
    bus.sim
        .device(id)
        .expect("a device")
        .params
        .raw(index::MAX_CUR)
}

fn ids_of(list: &Value) -> Vec<u64> {
    list.as_array()
        .expect("a list")
        .iter()
        .map(|d| d["id"].as_u64().expect("an id"))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn write_to_all_skips_offline_and_unmanaged_devices_and_says_so() {
    // Three rev 2.0.8 devices (the frame to 0xFF is open to them); the
    // daemon manages 1 and 2; 2's replies are lost (offline, still listening).
    let bus = start_with(3, None, "2.0.8", |_| {}).await;
    bus.wait_snapshot("every revision known", |s| {
        s.devices.values().filter(|d| d.firmware.is_some()).count() == 3
    })
    .await;
    let options = Options {
        managed: BTreeMap::from([("sim0".to_string(), vec![1, 2])]),
        ..Default::default()
    };
    assert!(bus.server_state.control().set_options(options).is_ok());
    bus.sim.inject(Fault::DropReplies {
        dev_id: Some(2),
        rate: 1.0,
    });
    bus.wait_snapshot("device 2 offline", |s| {
        s.devices.get(&2).is_some_and(|d| !d.online)
    })
    .await;
    let before = (max_cur(&bus, 2), max_cur(&bus, 3));

    let r = bus
        .server
        .patch("/api/v1/buses/sim0/config", json!({"max_current_a": 2.0}))
        .await;
    let body = r.ok().clone();
    assert_eq!(ids_of(&body["devices"]), [1], "{body}");
    assert_eq!(body["devices"][0]["written"][0]["param"], "max_current_a");
    assert_eq!(
        body["skipped"],
        json!([{"id": 2, "reason": "offline"}, {"id": 3, "reason": "unmanaged"}]),
        "{body}"
    );
    assert_eq!(body["offline"], json!([2]));
    assert_eq!(body["method"], "per_device", "{body}");
    assert_eq!(max_cur(&bus, 1), 11650);
    assert_eq!((max_cur(&bus, 2), max_cur(&bus, 3)), before, "not written");
    let sent = config_writes(&bus, index::MAX_CUR);
    assert!(
        sent.iter().all(|(id, _)| *id == 1),
        "only device 1 was addressed: {sent:?}"
    );

    // Asked for: the unmanaged device too, never the offline one.
    let r = bus
        .server
        .patch(
            "/api/v1/buses/sim0/config?include_unmanaged=true",
            json!({"max_current_a": 1.5}),
        )
        .await;
    let body = r.ok().clone();
    assert_eq!(ids_of(&body["devices"]), [1, 3], "{body}");
    assert_eq!(
        body["skipped"],
        json!([{"id": 2, "reason": "offline"}]),
        "{body}"
    );
    assert_eq!(body["method"], "per_device", "{body}");
    assert_eq!(max_cur(&bus, 3), max_cur(&bus, 1));
    assert_eq!(
        max_cur(&bus, 2),
        before.0,
        "the offline device kept its value"
    );
    assert!(!config_writes(&bus, index::MAX_CUR)
        .iter()
        .any(|(id, _)| *id == 2 || *id == ALL_DEVICES));

    // Every device online and asked: the one frame to 0xFF is used.
    bus.sim.inject(Fault::ClearAll);
    bus.wait_snapshot("device 2 online", |s| {
        s.devices.get(&2).is_some_and(|d| d.online)
    })
    .await;
    let r = bus
        .server
        .patch(
            "/api/v1/buses/sim0/config?include_unmanaged=true",
            json!({"max_current_a": 1.0}),
        )
        .await;
    let body = r.ok().clone();
    assert_eq!(body["method"], "one_frame", "{body}");
    assert_eq!(ids_of(&body["devices"]), [1, 2, 3], "{body}");
    assert_eq!(body["skipped"], json!([]));
    let raw = max_cur(&bus, 1);
    assert_eq!((max_cur(&bus, 2), max_cur(&bus, 3)), (raw, raw));
}
