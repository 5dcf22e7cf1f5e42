//! The simulator over a real pseudo-terminal, with the protocol module as the
//! host: power-up, reads, enable/align/run, motion, jog, flash, id, baud.

mod sim_support;

use std::time::Duration;

use jointd::protocol::reply::fsm;
use jointd::protocol::{Command, Control, InfoBlock, ReplyBody};
use sim_support::*;

#[test]
fn power_up_announces_info01_then_answers_polls() {
    let (sim, mut host) = pty(config(&[3]));
    let hello = host.recv(WAIT).expect("power-up INFO_01");
    assert_eq!(hello.dev_id, 3);
    let ReplyBody::Info01(info) = hello.body() else {
        panic!("not INFO_01: {hello:?}")
    };
    assert_eq!(info.fsm, fsm::READY);
    assert_eq!(info.soft_ver, 128);
    assert!((info.vbus_v() - 12.0).abs() < 0.5);
    let r = host.read(3, InfoBlock::Info02).expect("INFO_02 reply");
    assert_eq!((r.dev_id, r.index), (3, 2));
    assert_eq!(sim.stats().replies, 1);
    assert_eq!(sim.stats().announcements, 1);
}

#[test]
fn enable_goes_through_align_to_run_and_disable_to_ready() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("power-up INFO_01");
    host.send(Command::Control(Control::enable(1)));
    wait_for("align", || (sim.device(1)?.fsm == fsm::ALIGN).then_some(()));
    let fsm_now = |host: &mut Host| match host.read(1, InfoBlock::Info01).map(|r| r.body()) {
        Some(ReplyBody::Info01(i)) => Some(i.fsm),
        _ => None,
    };
    wait_for("run", || (fsm_now(&mut host)? == fsm::RUN).then_some(()));
    host.send(Command::Control(Control::disable(1)));
    wait_for("ready", || {
        (fsm_now(&mut host)? == fsm::READY).then_some(())
    });
    // A second enable since power-up skips alignment.
    host.send(Command::Control(Control::enable(1)));
    assert_eq!(fsm_now(&mut host), Some(fsm::RUN));
    let _ = Duration::ZERO;
}
