//! Firmware profiles as a host sees them: `--firmware` / `--sim-firmware`
//! on the command line, and a bus mixing a rev 2.0.8 device (id 1) with a
//! V2.0.1 one (id 2) driven with frames over the in-memory line. The
//! behaviour tables themselves are tested with made-up instants in
//! `src/sim/firmware_tests.rs`.

mod support;

use std::process::Command as Process;

use jointd::protocol::params::{index, Revision};
use jointd::protocol::status::fsm;
use jointd::protocol::units::angle_raw_saturating;
use jointd::protocol::{
    BroadcastEnable, Command, ConfigParam, Control, ControlOp, CrcCoverage, InfoBlock, ReplyBody,
    ALL_DEVICES,
};
use jointd::sim::{Firmware, SimHandle};
use support::sim::*;

fn jointd(args: &[&str]) -> (bool, String) {
    let out = Process::new(env!("CARGO_BIN_EXE_jointd"))
        .args(args)
        .output()
        .expect("run jointd");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_firmware_specs_are_refused_with_the_reason() {
    for (spec, says) in [
        ("2.0.5", "`2.0.5` is not a protocol revision"),
        ("", "empty"),
        ("1-2=2.0.8,2.0.1", "not IDS=REV"),
        ("1=2.0.8,1=2.0.1", "device 1 is given two revisions"),
        ("9=2.0.8", "names device 9, which is not on the bus"),
    ] {
        let (ok, stderr) = jointd(&["sim", "--ids", "1-2", "--firmware", spec]);
        assert!(!ok, "{spec:?} accepted");
        assert!(
            stderr.contains("jointd sim: bad firmware"),
            "{spec:?}: {stderr}"
        );
        assert!(stderr.contains(says), "{spec:?}: {stderr}");
    }
    // The daemon refuses before it listens.
    let (ok, stderr) = jointd(&[
        "--sim",
        "2",
        "--sim-firmware",
        "3=2.0.8",
        "--listen",
        "127.0.0.1:0",
    ]);
    assert!(!ok);
    assert!(stderr.contains("not on the bus"), "{stderr}");
    let (ok, stderr) = jointd(&["--sim-firmware", "2.0.8", "--listen", "127.0.0.1:0"]);
    assert!(!ok && stderr.contains("--sim"), "needs --sim: {stderr}");
}

/// Devices 1 (rev 2.0.8) and 2 (V2.0.1), booted.
fn mixed() -> (SimHandle, Host) {
    let mut cfg = config(&[1, 2]);
    cfg.firmware = Firmware::parse("1=2.0.8").unwrap();
    let (sim, mut host) = memory(cfg);
    for _ in 0..2 {
        host.recv(WAIT).expect("power-up INFO_01");
    }
    (sim, host)
}

fn running(sim: &SimHandle, id: u8) -> bool {
    sim.device(id).is_some_and(|d| d.fsm == fsm::RUN)
}

#[test]
fn a_rev_2_0_8_host_program_moves_only_the_2_0_8_joint() {
    let (sim, mut host) = mixed();
    assert_eq!(sim.device(1).map(|d| d.firmware), Some(Revision::V2_0_8));
    assert_eq!(sim.device(2).map(|d| d.firmware), Some(Revision::V2_0_1));
    // What rev 2.0.8 host programs send: enable, then angles with EN = 0
    // and no speed (the limit at index 30 applies).
    host.send(Command::Control(Control::enable(ALL_DEVICES)));
    wait_for("both running", || {
        (running(&sim, 1) && running(&sim, 2)).then_some(())
    });
    host.send(Command::Control(Control {
        dev_id: ALL_DEVICES,
        op: ControlOp::SetRefRev208,
        pos_ref: angle_raw_saturating(15.0),
        spd_ref: 0,
        cur_ref: 0,
    }));
    wait_for("the 2.0.8 joint at 15°", || {
        sim.device(1)
            .filter(|d| (d.angle_deg - 15.0).abs() < 0.2)
            .map(|_| ())
    });
    let old = sim.device(2).unwrap();
    assert!(
        old.angle_deg.abs() < 0.1 && old.target_deg.abs() < 0.1,
        "{old:?}"
    );
}

#[test]
fn info_07_tells_the_revisions_apart_on_the_wire() {
    let (sim, mut host) = mixed();
    write(&mut host, ALL_DEVICES, ConfigParam::Sn(0x1234));
    let reply = host
        .read(1, InfoBlock::Info07)
        .expect("2.0.8 answers INFO_07");
    assert_eq!(
        reply.body(),
        ReplyBody::Info07([0x34, 0x12, 0, 0, 0, 0, 0, 0])
    );
    assert!(
        host.read(2, InfoBlock::Info07).is_none(),
        "V2.0.1 is silent"
    );
    // The V2.0.1 device still answers what it knows, and did not store SN.
    assert!(host.read(2, InfoBlock::Info01).is_some());
    assert_eq!(sim.device(2).map(|d| d.params.raw(index::SN)), Some(0));
    let s = sim.stats();
    assert_eq!(s.replies, 2, "INFO_07 of 1 and INFO_01 of 2, nothing else");
}

#[test]
fn the_e1_enable_broadcast_enables_only_2_0_8_devices() {
    let (sim, mut host) = mixed();
    let mut ops = [0u8; 16];
    ops[..2].fill(ControlOp::Enable as u8);
    host.send(Command::BroadcastEnableUnverified(BroadcastEnable {
        ops,
        crc: CrcCoverage::HeadAndValues,
    }));
    wait_for("the 2.0.8 device enabled", || {
        sim.device(1).filter(|d| d.enabled).map(|_| ())
    });
    assert!(!sim.device(2).unwrap().enabled);
    // Both devices heard the frame: the V2.0.1 one refused it, nothing was lost.
    assert_eq!(sim.stats().crc_errors, 0);
    host.send(Command::BroadcastEnableUnverified(BroadcastEnable {
        ops,
        crc: CrcCoverage::Values,
    }));
    wait_for("the V2.0.1 device enabled by the table layout", || {
        sim.device(2).filter(|d| d.enabled).map(|_| ())
    });
}
