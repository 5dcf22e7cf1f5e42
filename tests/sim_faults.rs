//! Fault injection and the less common SPEC behaviours, mostly over the fast
//! in-memory line (the unplug test also runs over a pty), and the adapter
//! faults `jointd doctor` tells apart (an echo, a count that never falls).

mod support;

use std::time::Duration;

use jointd::protocol::status::{fault, fsm};
use jointd::protocol::units::{angle_to_raw, speed_limit_to_raw, speed_to_raw};
use jointd::protocol::{
    BroadcastSpd, Command, Config, ConfigParam, Control, CtrlMode, FirmwareVersion, Group,
    InfoBlock, ReplyBody, ALL_DEVICES,
};
use jointd::sim::{AdapterModel, Fault, SimHandle};
use jointd::transport::is_hangup;
use jointd::transport::tty::TtyPort;
use support::sim::*;

const FW: FirmwareVersion = FirmwareVersion(128);

fn booted(ids: &[u8]) -> (SimHandle, Host) {
    let (sim, mut host) = memory(config(ids));
    for _ in ids {
        host.recv(WAIT).expect("power-up INFO_01");
    }
    (sim, host)
}

fn enable_and_run(sim: &SimHandle, host: &mut Host, id: u8) {
    host.send(Command::Control(Control::enable(id)));
    wait_for("run", || (sim.device(id)?.fsm == fsm::RUN).then_some(()));
}

#[test]
fn a_stall_engages_protection_bursts_on_a_new_command_then_faults() {
    let mut cfg = config(&[1]);
    // Long enough that the protection and burst states are easy to catch.
    cfg.stall_fault_after = Duration::from_millis(2000);
    let (sim, mut host) = memory(cfg);
    host.recv(WAIT).expect("power-up INFO_01");
    write(&mut host, 1, ConfigParam::CurLv1DelayMs(50));
    write(&mut host, 1, ConfigParam::CurRecvWinMs(50));
    write(&mut host, 1, ConfigParam::PlusTime(40));
    enable_and_run(&sim, &mut host, 1);
    sim.inject(Fault::Stall {
        dev_id: 1,
        at_deg: Some(2.0),
    });
    let spd = speed_limit_to_raw(10_000.0, FW).unwrap();
    host.send(Command::Control(Control::set_ref(
        1,
        angle_to_raw(40.0).unwrap(),
        spd,
    )));
    wait_for("protection", || {
        sim.device(1)?.protection_active.then_some(())
    });
    let cap = 873.0 / 32767.0 * 5.625;
    let d = sim.device(1).unwrap();
    assert!(d.blocked && (d.angle_deg - 2.0).abs() < 0.01);
    assert!(
        d.q_current_ref_a.abs() <= cap + 1e-6,
        "the reference capped at the protection limit"
    );
    // The current loop follows the lowered cap within a millisecond or so.
    wait_for("the current down to the protection limit", || {
        (sim.device(1)?.q_current_a.abs() <= cap + 1e-3).then_some(())
    });
    host.send(Command::Control(Control::set_ref(
        1,
        angle_to_raw(41.0).unwrap(),
        spd,
    )));
    wait_for("a new command bursts", || {
        sim.device(1)?.bursting.then_some(())
    });
    wait_for("stall fault", || {
        let i = info01(&mut host, 1)?;
        (i.fsm == fsm::FAULT && i.err_code == fault::STALL).then_some(())
    });
    assert!(
        sim.device(1).unwrap().temp_c > 29.0,
        "pushing warmed the winding"
    );
    host.send(Command::Control(Control::disable(1)));
    assert_eq!(
        info01(&mut host, 1).map(|i| (i.fsm, i.err_code)),
        Some((fsm::READY, 0))
    );
}

#[test]
fn a_power_cycle_reannounces_and_reloads_flash() {
    let mut cfg = config(&[1]);
    cfg.align_time = Duration::from_millis(500);
    let (sim, mut host) = memory(cfg);
    host.recv(WAIT).expect("power-up INFO_01");
    enable_and_run(&sim, &mut host, 1);
    write(&mut host, 1, ConfigParam::MaxCur(123));
    let r = host.read(1, InfoBlock::Info04).unwrap();
    assert!(matches!(r.body(), ReplyBody::Info04(i) if i.max_current == 123));
    sim.inject(Fault::PowerCycle { dev_id: 1 });
    let hello = host.recv(WAIT).expect("re-announcement");
    assert!(matches!(hello.body(), ReplyBody::Info01(i) if i.fsm == fsm::READY));
    let r = host.read(1, InfoBlock::Info04).unwrap();
    assert!(matches!(r.body(), ReplyBody::Info04(i) if i.max_current == 4368));
    host.send(Command::Control(Control::enable(1)));
    assert_eq!(
        info01(&mut host, 1).map(|i| i.fsm),
        Some(fsm::ALIGN),
        "alignment again after power-up"
    );
    assert_eq!(sim.stats().announcements, 2);
}

#[test]
fn reboot_command_reannounces() {
    let (sim, mut host) = booted(&[4]);
    write(&mut host, 4, ConfigParam::Reboot(0));
    let hello = host.recv(WAIT).expect("announcement after REBOOT");
    assert_eq!((hello.dev_id, hello.index), (4, 1));
    assert_eq!(sim.stats().announcements, 2);
}

#[test]
fn under_voltage_reports_and_faults_an_enabled_device() {
    let (sim, mut host) = booted(&[1]);
    sim.inject(Fault::UnderVoltage {
        dev_id: 1,
        on: true,
    });
    let i = info01(&mut host, 1).unwrap();
    assert_eq!((i.fsm, i.err_code), (fsm::READY, fault::HW_UNDER_VOLTAGE));
    assert!(i.vbus_v() < 7.0);
    host.send(Command::Control(Control::enable(1)));
    assert_eq!(info01(&mut host, 1).map(|i| i.fsm), Some(fsm::FAULT));
    sim.inject(Fault::UnderVoltage {
        dev_id: 1,
        on: false,
    });
    host.send(Command::Control(Control::disable(1)));
    let i = info01(&mut host, 1).unwrap();
    assert_eq!((i.fsm, i.err_code), (fsm::READY, 0));
    assert!(i.vbus_v() > 11.0);
}

#[test]
fn corrupted_and_dropped_replies_and_extra_turnaround() {
    let (sim, mut host) = booted(&[1, 2]);
    sim.inject(Fault::CorruptRate(1.0));
    assert!(host.read(1, InfoBlock::Info01).is_none());
    assert!(
        sim.stats().crc_errors >= 1,
        "the request was garbled on the way"
    );
    sim.inject(Fault::ClearAll);
    sim.inject(Fault::DropReplies {
        dev_id: Some(2),
        rate: 1.0,
    });
    assert!(host.read(2, InfoBlock::Info01).is_none());
    assert!(host.read(1, InfoBlock::Info01).is_some());
    assert_eq!(sim.stats().dropped_replies, 1);
    sim.inject(Fault::ExtraTurnaround(Duration::from_millis(3)));
    sim.clear_frame_log();
    assert!(host.read(1, InfoBlock::Info01).is_some());
    let log = sim.frame_log();
    assert_eq!(log[1].start - log[0].end, Duration::from_micros(3100));
}

#[test]
fn comm_silent_ignores_everything_but_itself() {
    let (sim, mut host) = booted(&[1]);
    write(&mut host, 1, ConfigParam::CommSilent(1));
    assert!(host.read(1, InfoBlock::Info01).is_none());
    host.send(Command::Control(Control::enable(1)));
    assert!(sim.device(1).unwrap().silent);
    write(&mut host, 1, ConfigParam::CommSilent(0));
    assert_eq!(
        info01(&mut host, 1).map(|i| i.fsm),
        Some(fsm::READY),
        "the enable was ignored"
    );
}

#[test]
fn speed_mode_turns_at_the_broadcast_speed() {
    let (sim, mut host) = booted(&[1, 2]);
    host.send(Command::Control(Control::enable(ALL_DEVICES)));
    wait_for("both run", || {
        sim.devices()
            .iter()
            .all(|d| d.fsm == fsm::RUN)
            .then_some(())
    });
    write(&mut host, 2, ConfigParam::CtrlMode(CtrlMode::Speed));
    let mut spd = [0i16; 8];
    spd[1] = speed_to_raw(-5000.0, FW).unwrap();
    host.send(Command::BroadcastSpd(BroadcastSpd {
        group: Group::Low,
        spd_ref: spd,
    }));
    let want = -5000.0 * 6.0 / 568.81;
    wait_for("cruise", || {
        let d = sim.device(2)?;
        ((d.velocity_deg_s - want).abs() < 0.01 * want.abs()).then_some(())
    });
    let r = host.read(2, InfoBlock::Info02).unwrap();
    let ReplyBody::Info02(i) = r.body() else {
        panic!()
    };
    assert!(
        (i.speed_rpm(FW) + 5000.0).abs() < 50.0,
        "rotor {} rpm",
        i.speed_rpm(FW)
    );
    assert!(i.angle_deg() < 0.0);
    assert_eq!(
        sim.device(1).unwrap().velocity_deg_s,
        0.0,
        "device 1 got speed 0 in position mode"
    );
}

#[test]
fn unplug_hangs_up_the_memory_line_and_replug_restores_it() {
    let (sim, mut host) = booted(&[1]);
    sim.inject(Fault::Unplug);
    let mut buf = [0u8; 20];
    let err = host
        .port
        .read_timeout(&mut buf, Duration::from_millis(10))
        .unwrap_err();
    assert!(is_hangup(&err));
    assert!(sim.stats().unplugged);
    sim.inject(Fault::Replug);
    assert!(host.read(1, InfoBlock::Info01).is_some());
}

#[test]
fn unplug_hangs_up_the_pty_and_replug_serves_the_same_path() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("power-up INFO_01");
    let path = sim.device_path().unwrap();
    sim.inject(Fault::Unplug);
    let mut buf = [0u8; 20];
    let err = host
        .port
        .read_timeout(&mut buf, Duration::from_millis(100))
        .unwrap_err();
    assert!(is_hangup(&err), "{err}");
    assert!(!path.exists(), "an unplugged adapter's node disappears");
    sim.inject(Fault::Replug);
    let (port, _) = TtyPort::open(&path, BAUD).expect("reopen by the same path");
    let mut host = Host {
        port: Box::new(port),
        decoder: Default::default(),
    };
    assert!(host.read(1, InfoBlock::Info01).is_some());
}

#[test]
fn an_echoing_adapter_hands_each_host_frame_back_as_sent() {
    let mut cfg = config(&[1]);
    cfg.echo = true;
    let (sim, mut host) = memory(cfg);
    host.recv(WAIT).expect("power-up INFO_01");
    // A read of an id nobody has: the echo is all that comes back.
    let read = Command::Config(Config::read(7, InfoBlock::Info01));
    host.send(read);
    let mut got = Vec::new();
    wait_for("the echo", || {
        got.extend(host.drain(Duration::from_millis(20)));
        (got.len() >= 20).then_some(())
    });
    assert_eq!(got, read.encode().to_vec(), "the frame as sent, once");
    assert_eq!(sim.stats().echoes, 1);
    sim.inject(Fault::Echo(false));
    // The reply comes after the echo would have: none was counted.
    host.send(Command::Config(Config::read(1, InfoBlock::Info01)));
    assert!(host.recv(WAIT).is_some(), "the reply");
    assert_eq!(sim.stats().echoes, 1);
}

#[test]
fn a_stuck_count_never_falls_though_the_bytes_go_out() {
    let mut cfg = config(&[1]);
    cfg.adapter = AdapterModel::Ch340;
    let (sim, mut host) = memory(cfg);
    host.recv(WAIT).expect("power-up INFO_01");
    sim.inject(Fault::StuckCount(true));
    host.send(Command::Config(Config::read(1, InfoBlock::Info01)));
    assert!(
        host.recv(WAIT).is_some(),
        "the request went out and was answered"
    );
    assert_eq!(host.port.unsent(), Some(20), "its 20 bytes still counted");
    sim.inject(Fault::StuckCount(false));
    wait_for("the count to fall", || {
        (host.port.unsent() == Some(0)).then_some(())
    });
}
