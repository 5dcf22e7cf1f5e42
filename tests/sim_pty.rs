//! The simulator over a real pseudo-terminal, with the protocol module as the
//! host: power-up, every read, enable/align/run, motion, jog and re-zero,
//! flash across a restart, id change, baud change.

mod support;

use std::time::{Duration, Instant};

use jointd::protocol::status::fsm;
use jointd::protocol::units::{angle_to_raw, output_deg_per_s, speed_limit_to_raw};
use jointd::protocol::{
    BaudLevel, Command, ConfigParam, Control, FirmwareVersion, InfoBlock, Jog, JogDir, ReplyBody,
};
use jointd::sim::SimHandle;
use support::sim::*;

/// Enables `id` and waits for it to run.
fn enable(sim: &SimHandle, host: &mut Host, id: u8) {
    host.send(Command::Control(Control::enable(id)));
    wait_for("run", || (info01(host, id)?.fsm == fsm::RUN).then_some(()));
    assert!(sim.device(id).unwrap().aligned);
}

/// Jogs device 1 and waits until the jog (if it started) is over. The read
/// after the jog is answered only once the jog frame was heard (the wire keeps order).
fn jog(sim: &SimHandle, host: &mut Host, dir: JogDir) {
    host.send(Command::Jog(Jog { dev_id: 1, dir }));
    assert!(info01(host, 1).is_some());
    wait_for("jog done", || (!sim.device(1)?.jogging).then_some(()));
}

#[test]
fn power_up_announces_info01_then_answers_polls() {
    let (sim, mut host) = pty(config(&[3]));
    let hello = host.recv(WAIT).expect("power-up INFO_01");
    assert_eq!(hello.dev_id, 3);
    let ReplyBody::Info01(info) = hello.body() else {
        panic!("not INFO_01: {hello:?}")
    };
    assert_eq!(
        (info.fsm, info.err_code, info.soft_ver),
        (fsm::READY, 0, 128)
    );
    assert!((info.vbus_v() - 12.0).abs() < 0.5);
    assert!((15.0..45.0).contains(&info.temp_c()));
    let r = host.read(3, InfoBlock::Info02).expect("INFO_02 reply");
    assert_eq!((r.dev_id, r.index), (3, 2));
    let s = sim.stats();
    assert_eq!((s.replies, s.announcements, s.kinds.config_read), (1, 1, 1));
}

#[test]
fn every_read_answers_with_the_spec_layout() {
    let (_sim, mut host) = pty(config(&[2]));
    host.recv(WAIT).expect("power-up INFO_01");
    for block in InfoBlock::ALL {
        if block == InfoBlock::Info07 {
            // A V2.0.1 device (the default) does not know rev 2.0.8's INFO_07:
            // no reply (tests/sim_firmware.rs has the 2.0.8 answer).
            assert!(host.read(2, block).is_none(), "V2.0.1 answered INFO_07");
            continue;
        }
        let r = host
            .read(2, block)
            .unwrap_or_else(|| panic!("no reply to {block:?}"));
        assert_eq!((r.dev_id, r.index), (2, block.index()));
        match r.body() {
            ReplyBody::Info01(i) => assert_eq!((i.fsm, i.soft_ver), (fsm::READY, 128)),
            ReplyBody::Info02(i) => assert!(i.angle_deg().abs() < 0.1 && i.speed == 0),
            ReplyBody::Info03(g) => assert_eq!(
                (g.pos_kp, g.pos_kd, g.spd_kp, g.spd_ki),
                (4095, 4095, 1023, 81)
            ),
            ReplyBody::Info04(i) => {
                assert_eq!(
                    (i.lpf_level, i.baud_level, i.param_ver),
                    (1, BaudLevel::B500000 as u8, 3)
                );
                assert_eq!((i.max_current, i.protect_limit), (4368, 873));
            }
            ReplyBody::Info05(i) => assert_eq!(
                (
                    i.protect_cur_lv1,
                    i.protect_delay_lv1_ms,
                    i.recv_cur,
                    i.recover_delay_ms
                ),
                (2912, 600, 582, 400)
            ),
            ReplyBody::Info06(i) => assert_eq!((i.cold_dt, i.plus_t), (20, 4)),
            other => panic!("unexpected body {other:?}"),
        }
    }
    // RAM writes show up in the matching block.
    write(&mut host, 2, ConfigParam::PosKp(1000));
    write(&mut host, 2, ConfigParam::PosLpf(4));
    write(&mut host, 2, ConfigParam::CurRecvWinMs(250));
    write(&mut host, 2, ConfigParam::PlusTime(7));
    let body = |host: &mut Host, b| host.read(2, b).map(|r| r.body());
    assert!(
        matches!(body(&mut host, InfoBlock::Info03), Some(ReplyBody::Info03(g)) if g.pos_kp == 1000)
    );
    assert!(
        matches!(body(&mut host, InfoBlock::Info04), Some(ReplyBody::Info04(i)) if i.lpf_level == 4)
    );
    assert!(
        matches!(body(&mut host, InfoBlock::Info05), Some(ReplyBody::Info05(i)) if i.recover_delay_ms == 250)
    );
    assert!(
        matches!(body(&mut host, InfoBlock::Info06), Some(ReplyBody::Info06(i)) if i.plus_t == 7)
    );
}

#[test]
fn enable_goes_through_align_to_run_and_disable_to_ready() {
    let mut cfg = config(&[1]);
    // Long enough to catch the align state on a loaded machine.
    cfg.align_time = Duration::from_millis(500);
    let (sim, mut host) = pty(cfg);
    host.recv(WAIT).expect("power-up INFO_01");
    host.send(Command::Control(Control::enable(1)));
    assert_eq!(info01(&mut host, 1).map(|i| i.fsm), Some(fsm::ALIGN));
    wait_for("run", || {
        (info01(&mut host, 1)?.fsm == fsm::RUN).then_some(())
    });
    host.send(Command::Control(Control::disable(1)));
    assert_eq!(info01(&mut host, 1).map(|i| i.fsm), Some(fsm::READY));
    // A second enable since power-up skips alignment.
    host.send(Command::Control(Control::enable(1)));
    assert_eq!(info01(&mut host, 1).map(|i| i.fsm), Some(fsm::RUN));
    assert_eq!(sim.stats().kinds.control, 3);
}

#[test]
fn a_position_target_is_reached_at_the_commanded_speed() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("power-up INFO_01");
    enable(&sim, &mut host, 1);
    let fw = FirmwareVersion(128);
    let rpm = 10_000.0;
    let spd = speed_limit_to_raw(rpm, fw).unwrap();
    host.send(Command::Control(Control::set_ref(
        1,
        angle_to_raw(30.0).unwrap(),
        spd,
    )));
    sim.clear_frame_log();
    // Sample the angle through the wire until it settles.
    wait_for("target", || {
        let r = host.read(1, InfoBlock::Info02)?;
        let ReplyBody::Info02(i) = r.body() else {
            return None;
        };
        ((i.angle_deg() - 30.0).abs() < 0.05 && i.speed.abs() < 10).then_some(())
    });
    // Angle against simulated time: the instant each INFO_02 was sampled is
    // its reply's start minus the turnaround (from the frame log).
    let samples: Vec<(Instant, f64)> = sim
        .frame_log()
        .iter()
        .filter(|f| !f.from_host && f.bytes[6] == InfoBlock::Info02.index())
        .map(|f| {
            (
                f.start,
                f64::from(i16::from_le_bytes([f.bytes[14], f.bytes[15]])) / 128.0,
            )
        })
        .collect();
    // Cruise speed: least-squares slope over every sample between 9° and
    // 21°, clear of the LPF's start and finish; one late-scheduled sample
    // then moves the estimate little, where a two-point slope would not.
    let cruise: Vec<(f64, f64)> = samples
        .iter()
        .filter(|(_, a)| (9.0..=21.0).contains(a))
        .map(|(t, a)| (t.duration_since(samples[0].0).as_secs_f64(), *a))
        .collect();
    assert!(
        cruise.len() >= 5,
        "only {} samples while cruising",
        cruise.len()
    );
    let speed = slope(&cruise);
    let want = output_deg_per_s(rpm);
    assert!(
        (speed - want).abs() < 0.05 * want,
        "cruise {speed:.1} °/s, commanded {want:.1} °/s"
    );
}

/// Least-squares slope of `y` over `x`.
fn slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(sx, sy), (x, y)| (sx + x / n, sy + y / n));
    let (cov, var) = points.iter().fold((0.0, 0.0), |(c, v), (x, y)| {
        (c + (x - mx) * (y - my), v + (x - mx) * (x - mx))
    });
    cov / var
}

#[test]
fn jog_moves_then_rezeroes_and_fin_zero_rezeroes() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("power-up INFO_01");
    jog(&sim, &mut host, JogDir::Cw);
    assert_eq!(
        sim.device(1).unwrap().zero_deg,
        0.0,
        "jog needs an enabled device"
    );
    enable(&sim, &mut host, 1);
    jog(&sim, &mut host, JogDir::Cw);
    let d = sim.device(1).unwrap();
    assert!(
        (d.zero_deg - 5.0).abs() < 0.05,
        "moved +5° (zero now at {})",
        d.zero_deg
    );
    assert!(info01(&mut host, 1).unwrap().angle_deg().abs() < 0.05);
    jog(&sim, &mut host, JogDir::Ccw);
    assert!(
        (sim.device(1).unwrap().zero_deg - 2.0).abs() < 0.05,
        "then −3°"
    );
    // Move away, then zero at the current position.
    let spd = speed_limit_to_raw(20_000.0, FirmwareVersion(128)).unwrap();
    host.send(Command::Control(Control::set_ref(
        1,
        angle_to_raw(-10.0).unwrap(),
        spd,
    )));
    wait_for("-10°", || {
        ((info01(&mut host, 1)?.angle_deg() + 10.0).abs() < 0.05).then_some(())
    });
    write(&mut host, 1, ConfigParam::UpdateFinZero);
    assert!(info01(&mut host, 1).unwrap().angle_deg().abs() < 0.05);
}

#[test]
fn write_flash_survives_a_restart_and_ram_only_changes_do_not() {
    let dir = std::env::temp_dir().join(format!("jointd-sim-flash-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut cfg = config(&[1]);
    cfg.state_file = Some(dir.join("flash.json"));
    {
        let (sim, mut host) = pty(cfg.clone());
        host.recv(WAIT).expect("power-up INFO_01");
        write(&mut host, 1, ConfigParam::MaxCur(1000));
        write(&mut host, 1, ConfigParam::WriteFlash { key: 0xA5 });
        let res = host.recv(WAIT).expect("RES of WRITE_FLASH");
        assert_eq!(res.body(), ReplyBody::Res { index: 13, code: 1 });
        write(&mut host, 1, ConfigParam::WriteFlash { key: 0x00 });
        let res = host.recv(WAIT).expect("RES of a bad key");
        assert_eq!(res.body(), ReplyBody::Res { index: 13, code: 0 });
        write(&mut host, 1, ConfigParam::PosKp(77));
        sim.shutdown();
    }
    let (_sim, mut host) = pty(cfg);
    host.recv(WAIT).expect("power-up INFO_01 after restart");
    let r4 = host.read(1, InfoBlock::Info04).unwrap();
    assert!(matches!(r4.body(), ReplyBody::Info04(i) if i.max_current == 1000));
    let r3 = host.read(1, InfoBlock::Info03).unwrap();
    assert!(matches!(r3.body(), ReplyBody::Info03(g) if g.pos_kp == 4095));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn set_id_answers_from_the_new_id_and_persists() {
    let dir = std::env::temp_dir().join(format!("jointd-sim-id-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut cfg = config(&[1]);
    cfg.state_file = Some(dir.join("flash.json"));
    let (sim, mut host) = pty(cfg.clone());
    host.recv(WAIT).expect("power-up INFO_01");
    write(&mut host, 1, ConfigParam::SetId { new_id: 9 });
    let res = host.recv(WAIT).expect("RES of SET_ID");
    assert_eq!(
        (res.dev_id, res.body()),
        (9, ReplyBody::Res { index: 4, code: 1 })
    );
    assert!(host.read(1, InfoBlock::Info01).is_none(), "old id is gone");
    assert_eq!(host.read(9, InfoBlock::Info01).map(|r| r.dev_id), Some(9));
    sim.shutdown();
    drop(sim);
    let (sim, mut host) = pty(cfg);
    assert_eq!(
        host.recv(WAIT).map(|r| r.dev_id),
        Some(9),
        "restart announces the new id"
    );
    assert_eq!(sim.device(9).map(|d| d.slot), Some(0));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_baud_change_answers_then_listens_only_at_the_new_baud() {
    let (sim, mut host) = pty(config(&[1]));
    host.recv(WAIT).expect("power-up INFO_01");
    write(&mut host, 1, ConfigParam::BaudRate(BaudLevel::B115200));
    let res = host.recv(WAIT).expect("RES of BAUD_RATE, at the old baud");
    assert_eq!(res.body(), ReplyBody::Res { index: 15, code: 1 });
    assert!(
        host.read(1, InfoBlock::Info01).is_none(),
        "500000 is garbage to it now"
    );
    assert!(sim.stats().baud_mismatches >= 1);
    host.port.set_baud(115_200).unwrap();
    let r = host.read(1, InfoBlock::Info04).expect("answer at 115200");
    assert!(matches!(r.body(), ReplyBody::Info04(i) if i.baud_level == BaudLevel::B115200 as u8));
    // The reply took a 115200 frame time on the simulated wire.
    let log = sim.frame_log();
    let last = log.last().unwrap();
    assert_eq!((last.end - last.start).as_micros(), 1736);
}

#[test]
fn the_handle_is_shareable_and_dropping_the_last_one_stops_the_simulator() {
    fn shareable<T: Send + Sync + Clone>() {}
    shareable::<SimHandle>();
    let (sim, _host) = pty(config(&[1]));
    let path = sim.device_path().unwrap();
    let clone = sim.clone();
    drop(sim);
    assert!(path.exists(), "a clone keeps it running");
    assert!(clone.device(1).is_some());
    drop(clone);
    assert!(!path.exists(), "the link goes with the simulator");
}
