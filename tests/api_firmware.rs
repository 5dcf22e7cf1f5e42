//! Firmware revisions as the daemon handles them, against the simulator's
//! two profiles: detection (INFO_07 answered or not), the config setting,
//! the revision in the device views, the rev 2.0.8 parameters offered to
//! 2.0.8 devices only, the bus-wide config PATCH (one frame to 0xFF, or one
//! write per device), and an enable right after a disable on rev 2.0.8.

mod support;

use serde_json::{json, Value};

use jointd::bus::firmware::FirmwareSetting;
use jointd::protocol::command::index;
use jointd::protocol::params::Revision;
use jointd::protocol::{Command, Config, Frame, ALL_DEVICES};
use support::sim_bus::{start_with, SimBus};

async fn revisions_known(bus: &SimBus, n: usize) {
    bus.wait_snapshot("every revision known", |s| {
        s.devices.values().filter(|d| d.firmware.is_some()).count() == n
    })
    .await;
}

/// Waits (up to the suite's generous limit) until `ok` holds.
async fn eventually(what: &str, ok: impl Fn() -> bool) {
    let deadline = tokio::time::Instant::now() + support::sim_bus::WAIT;
    while !ok() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "timed out waiting for {what}"
        );
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
}

fn device(list: &Value, id: u64) -> &Value {
    list["devices"]
        .as_array()
        .and_then(|d| d.iter().find(|d| d["id"] == id))
        .expect("device listed")
}

/// Config frames of the host with `index`, as (addressed id, value).
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_device_is_asked_its_revision_and_shows_it() {
    let bus = start_with(2, None, "1=2.0.8", |_| {}).await;
    revisions_known(&bus, 2).await;
    let list = bus.server.get("/api/v1/buses/sim0/devices").await;
    let list = list.ok();
    assert_eq!(device(list, 1)["revision"], "2.0.8");
    assert_eq!(device(list, 2)["revision"], "2.0.1");
    let one = bus.server.get("/api/v1/buses/sim0/devices/1").await;
    let p = &one.ok()["protocol"];
    assert_eq!(
        (p["revision"].as_str(), p["source"].as_str()),
        (Some("2.0.8"), Some("detected"))
    );
    let serial = p["serial_number"].as_str().expect("INFO_07 bytes");
    let sim_sn = bus.sim.device(1).expect("device 1").params.raw(index::SN);
    assert!(
        serial.starts_with(&format!("{:02X} {:02X}", sim_sn & 0xFF, sim_sn >> 8)),
        "{serial} vs {sim_sn:#06x}"
    );
    let two = bus.server.get("/api/v1/buses/sim0/devices/2").await;
    assert_eq!(two.ok()["protocol"]["serial_number"], Value::Null);
    // The silence of the 2.0.1 device is an answer, not a timeout.
    let snap = bus.handle.snapshot();
    assert!(snap.counters.firmware_probes_unanswered >= 1);
    assert_eq!(snap.counters.timeouts, 0, "{:?}", snap.counters);
    assert!(snap
        .devices
        .values()
        .all(|d| d.online && d.missed_polls == 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_revision_set_in_the_config_is_taken_without_asking() {
    let bus = start_with(2, None, "2.0.8", |cfg| {
        cfg.firmware = FirmwareSetting::Fixed(Revision::V2_0_8);
    })
    .await;
    revisions_known(&bus, 2).await;
    let one = bus.server.get("/api/v1/buses/sim0/devices/1").await;
    assert_eq!(one.ok()["protocol"]["source"], "config");
    assert_eq!(bus.handle.snapshot().counters.firmware_probes, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rev_2_0_8_parameters_are_offered_to_2_0_8_devices_only() {
    let bus = start_with(2, None, "1=2.0.8", |_| {}).await;
    revisions_known(&bus, 2).await;
    let cfg1 = bus.server.get("/api/v1/buses/sim0/devices/1/config").await;
    let cfg1 = cfg1.ok();
    assert_eq!(cfg1["revision"], "2.0.8");
    assert_eq!(
        cfg1["write_only"],
        json!(["drv_ot_c", "spd_limit_rpm", "sn"])
    );
    assert!(cfg1["serial_number"].is_string() && cfg1["raw"]["info07"].is_string());
    let cfg2 = bus.server.get("/api/v1/buses/sim0/devices/2/config").await;
    let cfg2 = cfg2.ok();
    assert_eq!(
        (cfg2["revision"].as_str(), &cfg2["write_only"]),
        (Some("2.0.1"), &json!([]))
    );
    assert!(cfg2["serial_number"].is_null() && cfg2["raw"].get("info07").is_none());

    // The 2.0.8 device takes a speed limit (unverifiable: nothing shows it).
    let r = bus
        .server
        .patch(
            "/api/v1/buses/sim0/devices/1/config",
            json!({"spd_limit_rpm": 10000}),
        )
        .await;
    assert_eq!(r.ok()["written"][0]["verified_by"], "unverifiable");
    // Handed to the port, not read back: the device takes it a frame later.
    let speed_limit = || bus.sim.device(1).map(|d| d.params.raw(index::SPD_LIMIT));
    eventually("10000 rpm (Q15 6553 of 50000 rpm) on device 1", || {
        speed_limit() == Some(6553)
    })
    .await;
    // The 2.0.1 device is refused, before anything goes out.
    let before = config_writes(&bus, index::SPD_LIMIT).len();
    let r = bus
        .server
        .patch(
            "/api/v1/buses/sim0/devices/2/config",
            json!({"pos_kp": 1.0, "drv_ot_c": 80}),
        )
        .await;
    let p = r.problem(422);
    assert_eq!(p["field"], "drv_ot_c");
    assert!(
        p["detail"]
            .as_str()
            .is_some_and(|d| d.contains("needs rev 2.0.8") && d.contains("2.0.1 (detected)")),
        "{p}"
    );
    assert_eq!(config_writes(&bus, index::SPD_LIMIT).len(), before);
    assert!(
        config_writes(&bus, index::SET_POS_KP).is_empty(),
        "nothing written"
    );
    // Current mode: rev 2.0.8 only.
    let r = bus
        .server
        .put(
            "/api/v1/buses/sim0/devices/2/mode",
            json!({"mode": "current"}),
        )
        .await;
    assert_eq!(r.problem(422)["field"], "mode");
    let r = bus
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/mode",
            json!({"mode": "current"}),
        )
        .await;
    r.ok();
    let mode = || bus.sim.device(1).map(|d| d.mode);
    eventually("device 1 in current mode", || {
        mode() == Some(jointd::protocol::CtrlMode::Current)
    })
    .await;
    // Its reference is a current: position targets are refused, not misread.
    bus.server
        .post_empty("/api/v1/buses/sim0/devices/1/enable")
        .await
        .ok();
    let r = bus
        .server
        .put(
            "/api/v1/buses/sim0/devices/1/target",
            json!({"position_deg": 10}),
        )
        .await;
    assert_eq!(r.problem(409)["type"], "urn:jointd:problem:wrong-mode");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bus_of_2_0_8_devices_is_configured_with_one_frame_to_0xff() {
    let bus = start_with(3, None, "2.0.8", |_| {}).await;
    revisions_known(&bus, 3).await;
    let r = bus
        .server
        .patch(
            "/api/v1/buses/sim0/config",
            json!({"max_current_a": 2.0, "lpf_level": 3}),
        )
        .await;
    let body = r.ok();
    assert_eq!(body["method"], "one_frame");
    let ids: Vec<u64> = body["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [1, 2, 3]);
    for d in body["devices"].as_array().unwrap() {
        let verified: Vec<&str> = d["written"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w["verified_by"].as_str().unwrap())
            .collect();
        assert_eq!(verified, ["read_back", "read_back"], "{d}");
    }
    // One frame per parameter, to 0xFF, and every device has the values.
    assert_eq!(config_writes(&bus, index::MAX_CUR), [(ALL_DEVICES, 11650)]);
    assert_eq!(config_writes(&bus, index::POS_LPF_LV), [(ALL_DEVICES, 3)]);
    for id in 1..=3 {
        let d = bus.sim.device(id).expect("device");
        assert_eq!(
            (
                d.params.raw(index::MAX_CUR),
                d.params.raw(index::POS_LPF_LV)
            ),
            (11650, 3)
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bus_with_a_2_0_1_device_is_configured_one_device_at_a_time() {
    let bus = start_with(3, None, "1-2=2.0.8,3=2.0.1", |_| {}).await;
    revisions_known(&bus, 3).await;
    let r = bus
        .server
        .patch("/api/v1/buses/sim0/config", json!({"max_current_a": 1.5}))
        .await;
    assert_eq!(r.ok()["method"], "per_device");
    let sent = config_writes(&bus, index::MAX_CUR);
    assert_eq!(
        sent.iter().map(|(id, _)| *id).collect::<Vec<_>>(),
        [1, 2, 3]
    );
    for id in 1..=3 {
        assert_eq!(
            bus.sim.device(id).unwrap().params.raw(index::MAX_CUR),
            sent[0].1
        );
    }
    // A rev 2.0.8 parameter cannot go to a bus with a 2.0.1 device.
    let r = bus
        .server
        .patch("/api/v1/buses/sim0/config", json!({"spd_limit_rpm": 5000}))
        .await;
    assert!(r.problem(422)["detail"]
        .as_str()
        .unwrap()
        .contains("device 3 runs 2.0.1"));
    assert!(config_writes(&bus, index::SPD_LIMIT).is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_2_0_8_joint_enables_again_right_after_a_disable() {
    let bus = start_with(1, None, "2.0.8", |_| {}).await;
    revisions_known(&bus, 1).await;
    for _ in 0..3 {
        bus.server
            .post_empty("/api/v1/buses/sim0/devices/1/enable")
            .await
            .ok();
        bus.server
            .post_empty("/api/v1/buses/sim0/devices/1/disable")
            .await
            .ok();
    }
    bus.server
        .post_empty("/api/v1/buses/sim0/devices/1/enable")
        .await
        .ok();
    assert!(bus.sim.device(1).unwrap().enabled);
}
