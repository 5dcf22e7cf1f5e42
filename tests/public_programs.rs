//! The frames public host programs send (tests/vectors/public_programs.json:
//! ParaHandSDK recorded running against the simulator, E1_Hand_G474 derived by
//! reading its frame builders), replayed against the simulator: every frame
//! decodes with a name (never `invalid`), rev 2.0.8 devices do what the
//! programs asked, and V2.0.1 devices ignore what only rev 2.0.8 knows.

mod support;

use std::time::Duration;

use serde_json::Value;

use jointd::protocol::frame_json::frame_to_json;
use jointd::protocol::status::fsm;
use jointd::protocol::{Frame, FRAME_LEN};
use jointd::sim::{Firmware, SimHandle};
use support::sim::{config, memory, wait_for, Host, WAIT};

fn vectors() -> Value {
    let text = include_str!("vectors/public_programs.json");
    serde_json::from_str(text).expect("public_programs.json is JSON")
}

fn bytes(hex: &str) -> [u8; FRAME_LEN] {
    let v: Vec<u8> = hex
        .split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect();
    v.try_into().expect("20 bytes")
}

fn programs() -> Vec<Value> {
    vectors()["programs"].as_array().expect("programs").clone()
}

fn calls(program: &Value) -> &Vec<Value> {
    program["calls"].as_array().expect("calls")
}

fn frames(call: &Value) -> Vec<[u8; FRAME_LEN]> {
    call["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .map(|f| bytes(f.as_str().expect("hex")))
        .collect()
}

/// Devices 1 and 2 at the program's baud under `firmware`, booted.
fn bus(program: &Value, firmware: &str) -> (SimHandle, Host) {
    let mut cfg = config(&[1, 2]);
    cfg.baud = program["baud"]
        .as_u64()
        .and_then(|b| u32::try_from(b).ok())
        .expect("baud");
    cfg.firmware = Firmware::parse(firmware).expect("firmware");
    let (sim, mut host) = memory(cfg);
    for _ in 0..2 {
        host.recv(WAIT).expect("power-up INFO_01");
    }
    (sim, host)
}

fn send(host: &mut Host, call: &Value) {
    for f in frames(call) {
        host.port.write_all(&f).expect("write frame");
    }
}

/// The devices running (aligned, holding a target): what a program waits
/// for after an enable before it sends angles.
fn enabled(sim: &SimHandle) -> Vec<u64> {
    sim.devices()
        .iter()
        .filter(|d| d.fsm == fsm::RUN)
        .map(|d| u64::from(d.id))
        .collect()
}

#[test]
fn every_frame_of_every_program_decodes_with_a_name() {
    let mut n = 0;
    for p in programs() {
        for call in calls(&p) {
            for f in frames(call) {
                let frame = Frame::decode(&f).unwrap_or_else(|e| panic!("{}: {e}", call["call"]));
                let json = frame_to_json(&frame);
                assert_ne!(json["kind"], "invalid", "{}: {json}", call["call"]);
                n += 1;
            }
        }
    }
    assert_eq!(n, 40, "the vectors hold 40 frames");
}

#[test]
fn rev_2_0_8_devices_do_what_each_program_asked() {
    for p in programs() {
        let (sim, mut host) = bus(&p, "2.0.8");
        for call in calls(&p) {
            let what = call["call"].as_str().unwrap_or("?").to_owned();
            send(&mut host, call);
            let expect = &call["expect_2_0_8"];
            if let Some(r) = expect.get("reply") {
                let reply = host
                    .recv(WAIT)
                    .unwrap_or_else(|| panic!("{what}: no reply"));
                assert_eq!(
                    (u64::from(reply.dev_id), u64::from(reply.index)),
                    (r["dev_id"].as_u64().unwrap(), r["index"].as_u64().unwrap()),
                    "{what}"
                );
            }
            if let Some(ids) = expect.get("enabled") {
                let want: Vec<u64> = ids
                    .as_array()
                    .unwrap()
                    .iter()
                    .filter_map(Value::as_u64)
                    .collect();
                // Settled too: rev 2.0.8 passes through stop/brake, and
                // ignores an enable meanwhile (a program waits its cycle).
                let settled = || {
                    sim.devices()
                        .iter()
                        .all(|d| d.fsm == fsm::RUN || d.fsm == fsm::READY)
                };
                wait_for(&format!("{what}: enabled {want:?}"), || {
                    (enabled(&sim) == want && settled()).then_some(())
                });
            }
            if let Some(angles) = expect.get("angle_deg").and_then(Value::as_object) {
                for (id, deg) in angles {
                    let (id, deg): (u8, f64) = (id.parse().unwrap(), deg.as_f64().unwrap());
                    wait_for(&format!("{what}: device {id} at {deg}°"), || {
                        // At rest there, as the program's own wait leaves it.
                        sim.device(id)
                            .filter(|d| {
                                (d.angle_deg - deg).abs() < 0.5 && d.velocity_deg_s.abs() < 1.0
                            })
                            .map(drop)
                    });
                }
            }
            if let Some(params) = expect.get("params").and_then(Value::as_object) {
                for (id, values) in params {
                    for (idx, raw) in values.as_object().unwrap() {
                        let (id, idx): (u8, u8) = (id.parse().unwrap(), idx.parse().unwrap());
                        let raw = u16::try_from(raw.as_u64().unwrap()).unwrap();
                        wait_for(&format!("{what}: index {idx} of {id} = {raw}"), || {
                            sim.device(id)
                                .filter(|d| d.params.raw(idx) == raw)
                                .map(drop)
                        });
                    }
                }
            }
            // Replies nobody asked about (status polls) are not left for the next call.
            host.drain(Duration::from_millis(20));
        }
        assert_eq!(sim.stats().crc_errors, 0);
        assert_eq!(sim.stats().kinds.not_a_command, 0, "every frame understood");
    }
}

fn call<'a>(p: &'a Value, starts: &str) -> &'a Value {
    calls(p)
        .iter()
        .find(|c| c["call"].as_str().is_some_and(|s| s.starts_with(starts)))
        .unwrap_or_else(|| panic!("no call {starts}"))
}

#[test]
fn v2_0_1_devices_ignore_what_only_rev_2_0_8_knows() {
    let ps = programs();
    let (parahand, e1) = (&ps[0], &ps[1]);
    // The SDK's angle command has EN = 0: a no-op on V2.0.1.
    let (sim, mut host) = bus(parahand, "2.0.1");
    send(&mut host, call(parahand, "enable_motor(1, True)"));
    wait_for("device 1 enabled", || (enabled(&sim) == [1]).then_some(()));
    send(&mut host, call(parahand, "set_motor_angle(1"));
    // Ordering, not timing: a frame after it is handled after it.
    send(&mut host, call(parahand, "get_motor_status(2"));
    host.recv(WAIT).expect("INFO_01 of device 2");
    // A reference taken sets the target at once: none was.
    let d1 = sim.device(1).unwrap();
    assert!(d1.target_deg.abs() < 0.1, "{d1:?}");
    // The SDK's enable-all (can_id 0xB1) is not a V2.0.1 command.
    send(&mut host, call(parahand, "enable_motor(1, False)"));
    wait_for("device 1 disabled", || {
        enabled(&sim).is_empty().then_some(())
    });
    send(&mut host, call(parahand, "enable_all_motors(True)"));
    send(&mut host, call(parahand, "get_motor_status(2"));
    host.recv(WAIT).expect("INFO_01 of device 2");
    assert!(enabled(&sim).is_empty());

    // E1's 0xB155 with its CRC over the head too: refused by V2.0.1.
    let (sim, mut host) = bus(e1, "2.0.1");
    send(
        &mut host,
        call(e1, "fsm_bcast_en: enable broadcast 0xB155 enabling"),
    );
    send(&mut host, call(e1, "fsm_poll: INFO_01 read of device 2"));
    host.recv(WAIT).expect("INFO_01 of device 2");
    assert!(enabled(&sim).is_empty());
}
