//! Firmware profiles through the engine with made-up instants: each
//! behaviour of [`super::firmware`] on a bus that mixes a rev 2.0.8 device
//! (id 1) with a V2.0.1 one (id 2), which hear the same frames.

use std::time::{Duration, Instant};

use super::*;
use crate::protocol::params::{index, Revision};
use crate::protocol::status::{active_fault, fault, fault_history, fsm};
use crate::protocol::units::{angle_raw_saturating, current_raw_saturating};
use crate::protocol::{
    BroadcastEnable, Config, ConfigParam, Control, ControlOp, CrcCoverage, CtrlMode, InfoBlock,
    Message, Reply, ReplyBody, VendorCommand, ALL_DEVICES,
};
use crate::sim::faults::Fault;
use crate::sim::firmware::{default_serial, Firmware, START_TIME, STOP_TIME};

const BAUD: u32 = 500_000;
const ALIGN: Duration = Duration::from_millis(10);
/// Long enough for any frame and its reply to leave the line.
const SETTLE: Duration = Duration::from_millis(5);
const NEW: u8 = 1;
const OLD: u8 = 2;

struct Bus {
    e: Engine,
    t: Instant,
}

impl Bus {
    /// Booted (announced) devices `ids` under the firmware `spec`.
    fn new(ids: &[u8], spec: &str) -> Self {
        Self::with(ids, spec, |_| {})
    }

    fn with(ids: &[u8], spec: &str, tweak: impl FnOnce(&mut SimConfig)) -> Self {
        let t0 = Instant::now();
        let mut cfg = SimConfig::new(ids.to_vec(), BAUD);
        cfg.align_time = ALIGN;
        cfg.firmware = Firmware::parse(spec).unwrap();
        tweak(&mut cfg);
        let mut e = Engine::new(&cfg, t0).unwrap();
        let t = t0 + Duration::from_millis(50);
        assert_eq!(e.advance(t, Some(BAUD)).len(), ids.len(), "announcements");
        Self { e, t }
    }

    /// Sends frames back to back and returns what reached the host
    /// (`None`: garbage, e.g. collided replies).
    fn send(&mut self, cmds: &[Command]) -> Vec<Option<Reply>> {
        let bytes: Vec<u8> = cmds.iter().flat_map(|c| c.encode()).collect();
        self.e.on_host_bytes(&bytes, self.t, Some(BAUD));
        self.t += SETTLE * u32::try_from(cmds.len()).unwrap();
        self.e
            .advance(self.t, Some(BAUD))
            .iter()
            .map(
                |d| match Frame::decode(&d.bytes).map(|f| Message::from_frame(&f)) {
                    Ok(Ok(Message::Reply(r))) => Some(r),
                    _ => None,
                },
            )
            .collect()
    }

    fn wait(&mut self, d: Duration) {
        self.t += d;
        assert!(self.e.advance(self.t, Some(BAUD)).is_empty());
    }

    fn dev(&mut self, id: u8) -> DeviceView {
        let t = self.t;
        self.e.views(t).into_iter().find(|d| d.id == id).unwrap()
    }

    fn control(&mut self, c: Control) {
        assert!(self.send(&[Command::Control(c)]).is_empty());
    }

    fn write(&mut self, dev_id: u8, param: ConfigParam) -> Vec<Option<Reply>> {
        self.send(&[Command::Config(Config { dev_id, param })])
    }

    fn read(&mut self, dev_id: u8, block: InfoBlock) -> Option<Reply> {
        let mut got = self.send(&[Command::Config(Config::read(dev_id, block))]);
        assert!(got.len() <= 1);
        got.pop().flatten()
    }

    /// Enables both test devices and waits until both run.
    fn enable_all(&mut self) {
        self.control(Control::enable(ALL_DEVICES));
        self.wait(ALIGN * 5 + START_TIME * 2);
        assert_eq!(self.dev(NEW).fsm, fsm::RUN);
        assert_eq!(self.dev(OLD).fsm, fsm::RUN);
    }
}

fn mixed() -> Bus {
    Bus::new(&[NEW, OLD], "1=2.0.8")
}

fn q7(deg: f64) -> i16 {
    angle_raw_saturating(deg)
}

fn en0(dev_id: u8, pos_ref: i16, spd_ref: i16, cur_ref: i16) -> Control {
    Control {
        dev_id,
        op: ControlOp::SetRefRev208,
        pos_ref,
        spd_ref,
        cur_ref,
    }
}

#[test]
fn each_device_shows_its_revision() {
    let mut b = mixed();
    assert_eq!(b.dev(NEW).firmware, Revision::V2_0_8);
    assert_eq!(b.dev(OLD).firmware, Revision::V2_0_1);
    let json = serde_json::to_value(b.dev(NEW)).unwrap();
    assert_eq!(json["firmware"], "2.0.8");
}

#[test]
fn en_zero_moves_a_2_0_8_joint_and_not_a_2_0_1_joint() {
    let mut b = mixed();
    b.enable_all();
    b.control(en0(ALL_DEVICES, q7(20.0), 3000, 0));
    b.wait(Duration::from_secs(1));
    assert!(
        (b.dev(NEW).angle_deg - 20.0).abs() < 0.1,
        "{}",
        b.dev(NEW).angle_deg
    );
    assert!(b.dev(OLD).angle_deg.abs() < 0.1, "V2.0.1 ignores EN = 0");
    // The V2.0.1 joint is live: SET_REF moves it.
    b.control(Control::set_ref(OLD, q7(20.0), 3000));
    b.wait(Duration::from_secs(1));
    assert!((b.dev(OLD).angle_deg - 20.0).abs() < 0.1);
}

#[test]
fn speed_zero_moves_at_the_speed_limit_under_2_0_8_only_and_the_limit_caps() {
    let mut b = mixed();
    b.enable_all();
    b.control(Control::set_ref(ALL_DEVICES, q7(30.0), 0));
    b.wait(Duration::from_secs(1));
    assert!((b.dev(NEW).angle_deg - 30.0).abs() < 0.1, "at SPD_LIMIT");
    assert!(
        b.dev(OLD).angle_deg.abs() < 0.1,
        "V2.0.1: a limit of 0, as before"
    );
    // ~1000 rpm rotor: ~10.5 °/s at the output. V2.0.1 does not know index 30.
    assert!(b.write(ALL_DEVICES, ConfigParam::SpdLimit(655)).is_empty());
    b.control(Control::set_ref(ALL_DEVICES, q7(60.0), 13106));
    b.wait(Duration::from_millis(500));
    let (new, old) = (b.dev(NEW), b.dev(OLD));
    assert!(
        new.velocity_deg_s > 5.0 && new.velocity_deg_s < 11.0,
        "capped: {}",
        new.velocity_deg_s
    );
    assert!(new.angle_deg < 40.0, "{}", new.angle_deg);
    assert!(
        (old.angle_deg - 60.0).abs() < 0.1,
        "uncapped: {}",
        old.angle_deg
    );
    assert_eq!(
        (
            new.params.raw(index::SPD_LIMIT),
            old.params.raw(index::SPD_LIMIT)
        ),
        (655, 13106)
    );
}

#[test]
fn info_07_and_indices_28_to_31_exist_under_2_0_8_only() {
    let mut b = mixed();
    let sn = b.dev(NEW).params.raw(index::SN);
    assert_eq!(sn, default_serial(crate::sim::config::DEFAULT_SEED, 0));
    let Some(ReplyBody::Info07(bytes)) = b.read(NEW, InfoBlock::Info07).map(|r| r.body()) else {
        panic!("a 2.0.8 device answers INFO_07");
    };
    assert_eq!(bytes[..2], sn.to_le_bytes());
    assert_eq!(b.read(OLD, InfoBlock::Info07), None, "V2.0.1: no reply");
    // Writes of 28, 30, 31 are stored by 2.0.8 and ignored by 2.0.1 (neither replies).
    for p in [
        ConfigParam::DrvOtC(70),
        ConfigParam::SpdLimit(9000),
        ConfigParam::Sn(4242),
    ] {
        assert!(b.write(ALL_DEVICES, p).is_empty());
    }
    let (new, old) = (b.dev(NEW).params, b.dev(OLD).params);
    assert_eq!(
        (
            new.raw(index::DRV_OT),
            new.raw(index::SPD_LIMIT),
            new.raw(index::SN)
        ),
        (70, 9000, 4242)
    );
    assert_eq!(
        (
            old.raw(index::DRV_OT),
            old.raw(index::SPD_LIMIT),
            old.raw(index::SN)
        ),
        (90, 13106, 0)
    );
    let Some(ReplyBody::Info07(bytes)) = b.read(NEW, InfoBlock::Info07).map(|r| r.body()) else {
        panic!("INFO_07");
    };
    assert_eq!(bytes, [0x92, 0x10, 0, 0, 0, 0, 0, 0], "4242 = 0x1092");
    // INFO_06: bytes 0..2 as SPEC; the 2.0.8 tail is the simulator's layout.
    let new6 = b.read(NEW, InfoBlock::Info06).unwrap().data;
    let old6 = b.read(OLD, InfoBlock::Info06).unwrap().data;
    assert_eq!(new6[..2], old6[..2]);
    assert_eq!(old6[2..], [0; 6]);
    assert_eq!(
        (new6[4], u16::from_le_bytes([new6[5], new6[6]])),
        (70, 9000)
    );
}

#[test]
fn two_2_0_8_devices_have_distinct_serials() {
    let mut b = Bus::new(&[1, 2, 3], "2.0.8");
    let serials: Vec<u16> = (1..=3).map(|id| b.dev(id).params.raw(index::SN)).collect();
    assert!(serials[0] != serials[1] && serials[1] != serials[2] && serials[0] != serials[2]);
}

#[test]
fn current_mode_is_2_0_8_only_and_drives_the_q_current() {
    let mut b = mixed();
    b.enable_all();
    assert!(b
        .write(ALL_DEVICES, ConfigParam::CtrlMode(CtrlMode::Current))
        .is_empty());
    assert_eq!(b.dev(NEW).mode, CtrlMode::Current);
    assert_eq!(b.dev(OLD).mode, CtrlMode::Position, "V2.0.1 ignores mode 3");
    let amps = current_raw_saturating(0.3);
    b.control(Control {
        cur_ref: amps,
        ..Control::set_ref(ALL_DEVICES, 0, 0)
    });
    b.wait(Duration::from_millis(300));
    let (new, old) = (b.dev(NEW), b.dev(OLD));
    assert_eq!(new.cur_ref, amps);
    assert!((new.q_current_a - 0.3).abs() < 0.01, "{}", new.q_current_a);
    assert!(
        new.velocity_deg_s > 100.0 && new.angle_deg > 20.0,
        "{new:?}"
    );
    assert!(
        old.angle_deg.abs() < 0.1 && old.q_current_a.abs() < 0.1,
        "{old:?}"
    );
}

#[test]
fn a_config_write_to_0xff_reaches_every_device_and_res_replies_collide() {
    let mut b = Bus::new(&[1, 2, 3], "2=2.0.8");
    assert!(b.write(ALL_DEVICES, ConfigParam::PosKp(1000)).is_empty());
    for id in 1..=3 {
        assert_eq!(b.dev(id).params.raw(index::SET_POS_KP), 1000, "device {id}");
    }
    let got = b.write(ALL_DEVICES, ConfigParam::WriteFlash { key: 0xA5 });
    assert!(
        !got.is_empty() && got.iter().all(Option::is_none),
        "collided: {got:?}"
    );
    assert!(b.e.stats(b.t).collided_replies >= 3);
    for id in 1..=3 {
        assert_eq!(
            b.dev(id).flash.raw(index::SET_POS_KP),
            1000,
            "device {id} saved"
        );
    }
}

#[test]
fn enc_zero_answers_res_under_2_0_8_only() {
    let mut b = mixed();
    let res = |r: Option<Reply>| match r.map(|r| r.body()) {
        Some(ReplyBody::Res { index, code }) => Some((index, code)),
        _ => None,
    };
    let new = b.write(NEW, ConfigParam::UpdateEncZero).pop().flatten();
    assert_eq!(
        res(new),
        Some((index::UPDATE_ENC_ZERO, 1)),
        "success in ready"
    );
    assert!(
        b.write(OLD, ConfigParam::UpdateEncZero).is_empty(),
        "V2.0.1: no reply"
    );
    b.enable_all();
    let new = b.write(NEW, ConfigParam::UpdateEncZero).pop().flatten();
    assert_eq!(
        res(new),
        Some((index::UPDATE_ENC_ZERO, 0)),
        "failure while enabled"
    );
}

/// Distinct fsm values seen, sampling every millisecond for `span`.
fn states(b: &mut Bus, id: u8, span: Duration, seen: &mut Vec<u8>) {
    let step = Duration::from_millis(1);
    let mut left = span;
    while !left.is_zero() {
        let fsm = b.dev(id).fsm;
        if seen.last() != Some(&fsm) {
            seen.push(fsm);
        }
        b.wait(step);
        left = left.saturating_sub(step);
    }
}

#[test]
fn state_codes_follow_the_revision() {
    for (spec, power_up, run, stop) in [
        (
            "2.0.8",
            vec![fsm::INIT, fsm::PRECHARGE, fsm::READY],
            vec![fsm::READY, fsm::ALIGN, fsm::START, fsm::RUN],
            vec![fsm::RUN, fsm::STOP, fsm::READY],
        ),
        (
            "2.0.1",
            vec![fsm::READY],
            vec![fsm::READY, fsm::ALIGN, fsm::RUN],
            vec![fsm::RUN, fsm::READY],
        ),
    ] {
        // Power-up, watched from the first instant.
        let t0 = Instant::now();
        let mut cfg = SimConfig::new(vec![1], BAUD);
        cfg.align_time = ALIGN;
        cfg.firmware = Firmware::parse(spec).unwrap();
        let mut b = Bus {
            e: Engine::new(&cfg, t0).unwrap(),
            t: t0,
        };
        let mut seen = Vec::new();
        let mut step = || {
            let fsm = b.e.views(b.t)[0].fsm;
            if seen.last() != Some(&fsm) {
                seen.push(fsm);
            }
            b.t += Duration::from_micros(500);
            b.e.advance(b.t, Some(BAUD));
        };
        for _ in 0..40 {
            step();
        }
        assert_eq!(seen, power_up, "{spec} power-up");
        // Enable, then disable at rest.
        b.control(Control::enable(1));
        let mut seen = Vec::new();
        states(&mut b, 1, ALIGN + START_TIME * 3, &mut seen);
        assert_eq!(seen, run[1..], "{spec} enable");
        b.control(Control::disable(1));
        let mut seen = vec![fsm::RUN];
        states(&mut b, 1, STOP_TIME * 3, &mut seen);
        assert_eq!(seen, stop, "{spec} disable");
        // A second enable does not align again.
        b.control(Control::enable(1));
        let mut seen = vec![fsm::READY];
        states(&mut b, 1, START_TIME * 3, &mut seen);
        assert!(!seen.contains(&fsm::ALIGN), "{spec}: {seen:?}");
        assert_eq!(seen.last(), Some(&fsm::RUN));
    }
}

#[test]
fn a_2_0_8_joint_disabled_while_turning_brakes_then_stops() {
    let mut b = mixed();
    b.enable_all();
    assert!(b
        .write(ALL_DEVICES, ConfigParam::CtrlMode(CtrlMode::Speed))
        .is_empty());
    b.control(Control::set_ref(ALL_DEVICES, 0, 3000));
    b.wait(Duration::from_millis(300));
    assert!(b.dev(NEW).velocity_deg_s > 10.0);
    b.control(Control::disable(ALL_DEVICES));
    let mut new = Vec::new();
    let mut old = Vec::new();
    for _ in 0..200 {
        for (id, seen) in [(NEW, &mut new), (OLD, &mut old)] {
            let fsm = b.dev(id).fsm;
            if seen.last() != Some(&fsm) {
                seen.push(fsm);
            }
        }
        b.wait(Duration::from_millis(1));
    }
    assert_eq!(new, [fsm::BRAKE, fsm::STOP, fsm::READY]);
    assert_eq!(old, [fsm::READY]);
}

#[test]
fn the_fault_byte_keeps_a_latched_history_under_2_0_8() {
    let mut b = Bus::with(&[NEW, OLD], "1=2.0.8", |cfg| {
        cfg.stall_fault_after = Duration::from_millis(50);
    });
    b.e.inject(
        Fault::Stall {
            dev_id: NEW,
            at_deg: Some(1.0),
        },
        b.t,
    );
    b.e.inject(
        Fault::Stall {
            dev_id: OLD,
            at_deg: Some(1.0),
        },
        b.t,
    );
    b.enable_all();
    b.control(Control::set_ref(ALL_DEVICES, q7(30.0), 3000));
    b.wait(Duration::from_millis(300));
    let err = |b: &mut Bus, id| match b.read(id, InfoBlock::Info01).map(|r| r.body()) {
        Some(ReplyBody::Info01(i)) => (i.fsm, i.err_code),
        other => panic!("{other:?}"),
    };
    assert_eq!(
        err(&mut b, NEW),
        (fsm::FAULT, 0x88),
        "active stall, history stall"
    );
    assert_eq!(err(&mut b, OLD), (fsm::FAULT, fault::STALL));
    b.control(Control::disable(ALL_DEVICES));
    b.wait(STOP_TIME * 3);
    assert_eq!(
        err(&mut b, NEW),
        (fsm::READY, 0x80),
        "cleared, history kept"
    );
    assert_eq!(err(&mut b, OLD), (fsm::READY, 0));
    // Enable and disable again: the history stays.
    b.e.inject(Fault::ClearAll, b.t);
    b.enable_all();
    assert_eq!(err(&mut b, NEW).1, 0x80);
    // Only a power cycle clears it.
    b.e.inject(Fault::PowerCycle { dev_id: NEW }, b.t);
    b.t += Duration::from_millis(20);
    assert_eq!(
        b.e.advance(b.t, Some(BAUD)).len(),
        1,
        "the power-up INFO_01"
    );
    assert_eq!(err(&mut b, NEW), (fsm::READY, 0));
}

#[test]
fn drv_ot_faults_and_recovers_10_degrees_below_under_2_0_8_only() {
    let mut b = mixed();
    // At ambient (29 °C) any current heats the winding past 29 °C.
    assert!(b.write(ALL_DEVICES, ConfigParam::DrvOtC(29)).is_empty());
    b.control(Control::enable(ALL_DEVICES));
    b.wait(Duration::from_millis(200));
    let (new, old) = (b.dev(NEW), b.dev(OLD));
    assert_eq!(
        (new.fsm, active_fault(new.err_code)),
        (fsm::FAULT, fault::OVER_TEMPERATURE)
    );
    assert_eq!(
        (old.fsm, old.err_code),
        (fsm::RUN, 0),
        "V2.0.1 keeps its 90 °C"
    );
    // Disable does not clear a cause still present: the joint is above 19 °C.
    b.control(Control::disable(NEW));
    b.wait(STOP_TIME * 3);
    assert_eq!(active_fault(b.dev(NEW).err_code), fault::OVER_TEMPERATURE);
    b.control(Control::enable(NEW));
    assert_eq!(b.dev(NEW).fsm, fsm::FAULT, "enable faults again while hot");
    // A higher threshold: 29 °C is 10 °C below 60 °C, so it recovers.
    assert!(b.write(NEW, ConfigParam::DrvOtC(60)).is_empty());
    b.wait(Duration::from_millis(1));
    let new = b.dev(NEW);
    assert_eq!(new.fsm, fsm::READY);
    assert_eq!(
        (active_fault(new.err_code), fault_history(new.err_code)),
        (fault::NONE, fault::OVER_TEMPERATURE)
    );
}

#[test]
fn alignment_takes_longer_with_load_under_2_0_8() {
    let mut b = Bus::new(&[NEW, OLD, 3], "1=2.0.8,3=2.0.8");
    b.e.inject(
        Fault::Stall {
            dev_id: NEW,
            at_deg: None,
        },
        b.t,
    );
    b.e.inject(
        Fault::Stall {
            dev_id: OLD,
            at_deg: None,
        },
        b.t,
    );
    b.control(Control::enable(ALL_DEVICES));
    // Order of reaching run: the free 2.0.8 (1×) and the V2.0.1 device
    // (always 1×) long before the pressed 2.0.8 device (5×).
    let mut order = Vec::new();
    for _ in 0..200 {
        for id in [NEW, OLD, 3] {
            if b.dev(id).fsm == fsm::RUN && !order.contains(&id) {
                order.push(id);
            }
        }
        b.wait(Duration::from_millis(1));
    }
    assert_eq!(order.len(), 3);
    assert_eq!(order[2], NEW, "{order:?}");
}

#[test]
fn the_b155_crc_over_head_and_values_is_obeyed_by_2_0_8_only() {
    let mut b = mixed();
    let mut ops = [0u8; 16];
    ops[0] = ControlOp::Enable as u8;
    ops[1] = ControlOp::Enable as u8;
    let frame = |crc| Command::BroadcastEnableUnverified(BroadcastEnable { ops, crc });
    assert!(b.send(&[frame(CrcCoverage::HeadAndValues)]).is_empty());
    b.wait(ALIGN * 3);
    assert!(b.dev(NEW).enabled);
    assert!(
        !b.dev(OLD).enabled,
        "V2.0.1 refuses the head-and-values CRC"
    );
    assert!(b.send(&[frame(CrcCoverage::Values)]).is_empty());
    b.wait(ALIGN * 3);
    assert!(b.dev(OLD).enabled, "the table layout works on both");
}

#[test]
fn the_vendor_sdk_enable_all_frame_is_obeyed_by_2_0_8_only() {
    let mut b = mixed();
    let all = |op| {
        Command::Vendor(VendorCommand::EnableAll {
            dev_id: ALL_DEVICES,
            op,
        })
    };
    assert!(b.send(&[all(1)]).is_empty());
    b.wait(ALIGN * 3);
    assert!(b.dev(NEW).enabled);
    assert!(!b.dev(OLD).enabled, "V2.0.1 ignores can_id 0xB1");
    // The SDK's "disable" is op 0.
    assert!(b.send(&[all(0)]).is_empty());
    b.wait(STOP_TIME * 2);
    assert!(!b.dev(NEW).enabled);
    // Addressed to one id, only that device acts.
    let one = Command::Vendor(VendorCommand::EnableAll { dev_id: OLD, op: 1 });
    assert!(b.send(&[one]).is_empty());
    b.wait(ALIGN * 3);
    assert!(!b.dev(NEW).enabled && !b.dev(OLD).enabled);
}
