//! One simulated joint module: its state machine and what it does with each
//! command (SPEC §4, §5), driven by timestamps. No I/O: the engine hands it
//! decoded commands and sends what it answers.

use std::time::{Duration, Instant};

use crate::protocol::command::{index, WRITE_FLASH_KEY};
use crate::protocol::reply::{fault, fsm, Info01, Info02, RES_FAILURE, RES_SUCCESS};
use crate::protocol::units::{
    angle_deg, output_deg_per_s, speed_rpm, GEAR_RATIO, MAX_ANGLE_DEG, Q15_MAX,
};
use crate::protocol::{
    BroadcastEnable, Command, Config, ConfigParam, Control, ControlOp, CtrlMode, FirmwareVersion,
    Group, InfoBlock, JogDir, Reply, ReplyBody, ALL_DEVICES,
};

use super::params::{FlashImage, Params};
use super::physics::{Drive, Joint, Obstacle};
use super::rng::Rng;
use super::view::DeviceView;

/// Jog steps (SPEC §4.2).
const JOG_CW_DEG: f64 = 5.0;
const JOG_CCW_DEG: f64 = -3.0;
/// Rotor speed of a jog move, rpm.
const JOG_RPM: f64 = 6000.0;
/// A jog is over when the joint is this close to its goal and this slow.
const JOG_DONE_DEG: f64 = 0.02;
const JOG_DONE_DEG_S: f64 = 0.5;
/// Bus voltage: nominal, sag per ampere, noise, and under-voltage level.
const VBUS_V: f64 = 12.0;
const VBUS_SAG_V_PER_A: f64 = 0.3;
const VBUS_NOISE_V: f64 = 0.02;
const VBUS_UNDER_V: f64 = 6.0;
/// d-axis current noise, A; q-axis noise added to the modelled current.
const CURRENT_NOISE_A: f64 = 0.004;
/// Encoder noise on reported angles, degrees.
const ANGLE_NOISE_DEG: f64 = 0.004;
const Q7: f64 = 128.0;
const TEMP_OFFSET_C: f64 = 50.0;
const CURRENT_FULL_SCALE_A: f64 = 5.625;
const SECS_PER_MIN: f64 = 60.0;
const DEG_PER_TURN: f64 = 360.0;

/// Timing the device takes from the simulator's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceTiming {
    pub align_time: Duration,
    pub boot_delay: Duration,
    pub stall_fault_after: Duration,
    pub soft_ver: u8,
}

/// What handling a command produced.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    pub reply: Option<Reply>,
    /// Flash changed: the state file must be written.
    pub persist: bool,
}

impl Outcome {
    fn reply(r: Reply) -> Self {
        Self {
            reply: Some(r),
            persist: false,
        }
    }
}

#[derive(Debug, Clone)]
pub struct Device {
    pub slot: usize,
    pub id: u8,
    pub ram: Params,
    pub flash: Params,
    timing: DeviceTiming,
    fsm: u8,
    err_code: u8,
    aligned: bool,
    align_done_at: Option<Instant>,
    mode: CtrlMode,
    /// Target in reported degrees (after the zero offset).
    target: f64,
    spd_ref: i16,
    /// Physical angle that reads as 0°.
    zero: f64,
    joint: Joint,
    /// Reported-degree goal of a jog in progress.
    jog_goal: Option<f64>,
    silent: bool,
    boot_until: Instant,
    announce_at: Option<Instant>,
    under_voltage: bool,
    last: Instant,
    rng: Rng,
}

impl Device {
    /// A device powered up at `now`; it announces itself `stagger` after its boot delay.
    pub fn new(
        slot: usize,
        image: FlashImage,
        timing: DeviceTiming,
        now: Instant,
        stagger: Duration,
        seed: u64,
    ) -> Self {
        let mut d = Self {
            slot,
            id: image.id,
            ram: image.params,
            flash: image.params,
            timing,
            fsm: fsm::READY,
            err_code: fault::NONE,
            aligned: false,
            align_done_at: None,
            mode: CtrlMode::Position,
            target: 0.0,
            spd_ref: 0,
            zero: 0.0,
            joint: Joint::default(),
            jog_goal: None,
            silent: false,
            boot_until: now,
            announce_at: None,
            under_voltage: false,
            last: now,
            rng: Rng::new(seed),
        };
        d.power_up(now, stagger);
        d
    }

    /// Power-up (or reboot): RAM from flash, ready, unaligned, position mode.
    pub fn power_up(&mut self, now: Instant, stagger: Duration) {
        self.advance_to(now);
        self.ram = self.flash;
        self.fsm = fsm::READY;
        self.err_code = if self.under_voltage {
            fault::HW_UNDER_VOLTAGE
        } else {
            fault::NONE
        };
        self.aligned = false;
        self.align_done_at = None;
        self.mode = CtrlMode::Position;
        self.target = self.angle();
        self.spd_ref = 0;
        self.jog_goal = None;
        self.silent = false;
        self.joint.vel = 0.0;
        self.joint.current = 0.0;
        self.joint.prot = Default::default();
        self.boot_until = now + self.timing.boot_delay + stagger;
        self.announce_at = Some(self.boot_until);
    }

    pub fn flash_image(&self) -> FlashImage {
        FlashImage {
            id: self.id,
            params: self.flash,
        }
    }

    /// The baud the device listens and talks at.
    pub fn baud(&self) -> u32 {
        self.ram.baud()
    }

    fn firmware(&self) -> FirmwareVersion {
        FirmwareVersion(self.timing.soft_ver)
    }

    /// Reported output angle, degrees.
    pub fn angle(&self) -> f64 {
        self.joint.pos - self.zero
    }

    fn booting(&self, now: Instant) -> bool {
        now < self.boot_until
    }

    /// When the spontaneous power-up INFO_01 is due.
    pub fn announce_at(&self) -> Option<Instant> {
        self.announce_at
    }

    /// The power-up INFO_01, once it is due.
    pub fn take_announcement(&mut self, now: Instant) -> Option<Reply> {
        let due = self.announce_at.filter(|t| *t <= now)?;
        self.announce_at = None;
        self.advance_to(due);
        Some(self.info(InfoBlock::Info01))
    }

    /// Runs the physics and timers up to `now`.
    pub fn advance_to(&mut self, now: Instant) {
        while self.last < now {
            let edge = self
                .align_done_at
                .filter(|t| *t > self.last && *t <= now)
                .unwrap_or(now);
            let dt = (edge - self.last).as_secs_f64();
            let drive = self.drive();
            let bounds = (self.zero - MAX_ANGLE_DEG, self.zero + MAX_ANGLE_DEG);
            self.joint.advance(dt, drive, &self.ram, bounds);
            self.last = edge;
            if self.align_done_at == Some(edge) {
                self.finish_align();
            }
        }
        self.check_jog();
        self.check_faults();
    }

    fn finish_align(&mut self) {
        self.align_done_at = None;
        if self.fsm == fsm::ALIGN {
            self.aligned = true;
            self.fsm = fsm::RUN;
            self.target = self.angle();
        }
    }

    fn drive(&self) -> Drive {
        if self.fsm != fsm::RUN {
            return Drive::Off;
        }
        if let Some(goal) = self.jog_goal {
            let vmax = output_deg_per_s(JOG_RPM);
            return Drive::Position {
                target: goal + self.zero,
                vmax,
            };
        }
        let limit = self
            .rpm_of(self.ram.spd_limit.min(Q15_MAX as u16) as i16)
            .abs();
        let rpm = self.rpm_of(self.spd_ref).clamp(-limit, limit);
        match self.mode {
            CtrlMode::Position => Drive::Position {
                target: self.target + self.zero,
                vmax: output_deg_per_s(rpm.abs()),
            },
            CtrlMode::Speed => Drive::Speed {
                vel: output_deg_per_s(rpm),
            },
            CtrlMode::None | CtrlMode::Current => Drive::Off,
        }
    }

    fn rpm_of(&self, raw: i16) -> f64 {
        speed_rpm(raw, self.firmware())
    }

    fn check_jog(&mut self) {
        if let Some(goal) = self.jog_goal {
            let settled =
                (self.angle() - goal).abs() < JOG_DONE_DEG && self.joint.vel.abs() < JOG_DONE_DEG_S;
            if settled || self.fsm != fsm::RUN {
                self.jog_goal = None;
                if settled {
                    self.rezero();
                }
            }
        }
    }

    fn check_faults(&mut self) {
        if self.fsm != fsm::RUN {
            return;
        }
        if self.joint.blocked_s >= self.timing.stall_fault_after.as_secs_f64() {
            self.enter_fault(fault::STALL);
        } else if self.joint.temp_c > f64::from(self.ram.drv_ot) {
            self.enter_fault(fault::OVER_TEMPERATURE);
        }
    }

    fn enter_fault(&mut self, code: u8) {
        self.fsm = fsm::FAULT;
        self.err_code = code;
        self.jog_goal = None;
        self.align_done_at = None;
    }

    fn rezero(&mut self) {
        self.zero = self.joint.pos;
        self.target = 0.0;
    }

    /// Handles one command heard on the line at `now`.
    pub fn handle(&mut self, cmd: &Command, now: Instant) -> Outcome {
        self.advance_to(now);
        if self.booting(now) {
            return Outcome::default();
        }
        if self.silent && !self.is_silence_command(cmd) {
            return Outcome::default();
        }
        match cmd {
            Command::Control(c) if self.addressed(c.dev_id) => self.control(c, now),
            Command::Jog(j) if self.addressed(j.dev_id) => self.jog(j.dir),
            Command::Config(c) => return self.config(c, now),
            Command::BroadcastPos(b) => self.broadcast(b.group, &b.pos_ref, true),
            Command::BroadcastSpd(b) => self.broadcast(b.group, &b.spd_ref, false),
            Command::BroadcastEnableUnverified(b) => self.broadcast_enable(b, now),
            _ => {}
        }
        Outcome::default()
    }

    fn addressed(&self, dev_id: u8) -> bool {
        dev_id == self.id || dev_id == ALL_DEVICES
    }

    fn is_silence_command(&self, cmd: &Command) -> bool {
        matches!(cmd, Command::Config(Config { dev_id, param: ConfigParam::CommSilent(_) }) if self.addressed(*dev_id))
    }

    fn control(&mut self, c: &Control, now: Instant) {
        match c.op {
            ControlOp::Enable => self.enable(now),
            ControlOp::Disable => self.disable(),
            ControlOp::SetRef => self.set_ref(Some(c.pos_ref), Some(c.spd_ref)),
        }
    }

    fn enable(&mut self, now: Instant) {
        if self.fsm != fsm::READY {
            return;
        }
        if self.under_voltage {
            self.enter_fault(fault::HW_UNDER_VOLTAGE);
        } else if self.aligned {
            self.fsm = fsm::RUN;
            self.target = self.angle();
        } else {
            self.fsm = fsm::ALIGN;
            self.align_done_at = Some(now + self.timing.align_time);
        }
    }

    fn disable(&mut self) {
        self.fsm = fsm::READY;
        self.align_done_at = None;
        self.jog_goal = None;
        self.err_code = if self.under_voltage {
            fault::HW_UNDER_VOLTAGE
        } else {
            fault::NONE
        };
    }

    /// New references (SET_REF or a broadcast). In speed mode the angle is ignored.
    fn set_ref(&mut self, pos_ref: Option<i16>, spd_ref: Option<i16>) {
        if let Some(p) = pos_ref.filter(|_| self.mode != CtrlMode::Speed) {
            self.target = angle_deg(p).clamp(-MAX_ANGLE_DEG, MAX_ANGLE_DEG);
            self.jog_goal = None;
        }
        if let Some(s) = spd_ref {
            self.spd_ref = s;
        }
        self.joint.command_burst(&self.ram);
    }

    fn broadcast(&mut self, group: Group, values: &[i16; 8], is_pos: bool) {
        let Some((g, slot)) = Group::slot_of(self.id) else {
            return;
        };
        if g != group {
            return;
        }
        let v = values[slot];
        if is_pos {
            self.set_ref(Some(v), None);
        } else {
            self.set_ref(None, Some(v));
        }
    }

    fn broadcast_enable(&mut self, b: &BroadcastEnable, now: Instant) {
        let Some(op) = usize::from(self.id)
            .checked_sub(1)
            .and_then(|i| b.ops.get(i))
        else {
            return;
        };
        match *op {
            1 => self.enable(now),
            2 => self.disable(),
            _ => {}
        }
    }

    fn jog(&mut self, dir: JogDir) {
        if self.fsm != fsm::RUN {
            return;
        }
        let step = match dir {
            JogDir::Cw => JOG_CW_DEG,
            JogDir::Ccw => JOG_CCW_DEG,
            JogDir::None => return,
        };
        self.jog_goal = Some((self.angle() + step).clamp(-MAX_ANGLE_DEG, MAX_ANGLE_DEG));
    }

    fn config(&mut self, c: &Config, now: Instant) -> Outcome {
        if let ConfigParam::ReadInfo(block) = c.param {
            // Reads cannot be broadcast (SPEC §4.3): only the exact id answers.
            return if c.dev_id == self.id {
                Outcome::reply(self.info(block))
            } else {
                Outcome::default()
            };
        }
        if !self.addressed(c.dev_id) {
            return Outcome::default();
        }
        self.write(&c.param, now)
    }

    fn res(&self, index: u8, ok: bool) -> Reply {
        let code = if ok { RES_SUCCESS } else { RES_FAILURE };
        Reply::new(self.id, ReplyBody::Res { index, code })
    }

    fn write(&mut self, p: &ConfigParam, now: Instant) -> Outcome {
        match *p {
            ConfigParam::Reboot(_) => self.power_up(now, Duration::ZERO),
            ConfigParam::UpdateFinZero => self.rezero(),
            ConfigParam::SetId { new_id } => {
                self.id = new_id;
                return Outcome {
                    reply: Some(self.res(index::SET_ID, true)),
                    persist: true,
                };
            }
            ConfigParam::UpdateEncZero => {
                let idle = self.fsm == fsm::READY;
                if idle {
                    self.aligned = false;
                }
                return Outcome::reply(self.res(index::UPDATE_ENC_ZERO, idle));
            }
            ConfigParam::CommSilent(v) => self.silent = v != 0,
            ConfigParam::CtrlMode(m) => self.switch_mode(m),
            ConfigParam::WriteFlash { key } => return self.write_flash(key),
            ConfigParam::ReadFlash => self.ram = self.flash,
            ConfigParam::BaudRate(level) => {
                // The RES goes out at the old baud (the engine times it by the
                // request); from now on the device listens at the new one.
                self.ram.baud_level = level as u8;
                return Outcome::reply(self.res(index::BAUD_RATE, true));
            }
            ref other => {
                self.ram.apply(other);
            }
        }
        Outcome::default()
    }

    fn write_flash(&mut self, key: u8) -> Outcome {
        let ok = key == WRITE_FLASH_KEY;
        if ok {
            self.flash = self.ram;
        }
        Outcome {
            reply: Some(self.res(index::WRITE_FLASH, ok)),
            persist: ok,
        }
    }

    fn switch_mode(&mut self, m: CtrlMode) {
        if m == CtrlMode::None || m == self.mode {
            return;
        }
        self.mode = m;
        self.jog_goal = None;
        self.target = self.angle();
        if m == CtrlMode::Speed {
            self.spd_ref = 0;
        }
    }

    /// The INFO block a read asks for, from the current state.
    pub fn info(&mut self, block: InfoBlock) -> Reply {
        let body = match block {
            InfoBlock::Info01 => ReplyBody::Info01(self.info01()),
            InfoBlock::Info02 => ReplyBody::Info02(self.info02()),
            InfoBlock::Info03 => ReplyBody::Info03(self.ram.gains()),
            InfoBlock::Info04 => ReplyBody::Info04(self.ram.info04()),
            InfoBlock::Info05 => ReplyBody::Info05(self.ram.info05()),
            InfoBlock::Info06 => ReplyBody::Info06(self.ram.info06()),
            InfoBlock::Info07 => {
                let mut sn = [0u8; 8];
                sn[..2].copy_from_slice(&self.ram.sn.to_le_bytes());
                ReplyBody::Info07(sn)
            }
        };
        Reply::new(self.id, body)
    }

    fn vbus(&mut self) -> f64 {
        let base = if self.under_voltage {
            VBUS_UNDER_V
        } else {
            VBUS_V
        };
        base - VBUS_SAG_V_PER_A * self.joint.current.abs() + self.rng.noise(VBUS_NOISE_V)
    }

    fn info01(&mut self) -> Info01 {
        let angle = self.angle() + self.rng.noise(ANGLE_NOISE_DEG);
        Info01 {
            fsm: self.fsm,
            err_code: self.err_code,
            soft_ver: self.timing.soft_ver,
            temp_raw: (self.joint.temp_c + TEMP_OFFSET_C)
                .round()
                .clamp(0.0, 255.0) as u8,
            angle: q7(angle),
            vbus: (self.vbus() * Q7).round().clamp(0.0, f64::from(u16::MAX)) as u16,
        }
    }

    fn info02(&mut self) -> Info02 {
        let rotor_rpm = self.joint.vel * GEAR_RATIO * SECS_PER_MIN / DEG_PER_TURN;
        let base = self.firmware().speed_base_rpm();
        let powered = self.fsm == fsm::RUN || self.fsm == fsm::ALIGN;
        let noise = if powered { CURRENT_NOISE_A } else { 0.0 };
        let d = self.rng.noise(noise);
        let q = self.joint.current + self.rng.noise(noise);
        Info02 {
            d_cur: q15_current(d),
            q_cur: q15_current(q),
            speed: (rotor_rpm / base * Q15_MAX)
                .round()
                .clamp(-Q15_MAX, Q15_MAX) as i16,
            angle: q7(self.angle() + self.rng.noise(ANGLE_NOISE_DEG)),
        }
    }

    // ---- fault injection ----

    /// Puts an obstacle at `at_deg` (reported degrees), or right where the joint is.
    pub fn set_obstacle(&mut self, at_deg: Option<f64>, now: Instant) {
        self.advance_to(now);
        let at = at_deg.map_or(self.joint.pos, |a| a + self.zero);
        self.joint.obstacle = Some(Obstacle::at(at));
    }

    pub fn clear_obstacle(&mut self, now: Instant) {
        self.advance_to(now);
        self.joint.obstacle = None;
        self.joint.blocked_s = 0.0;
    }

    pub fn set_under_voltage(&mut self, on: bool, now: Instant) {
        self.advance_to(now);
        self.under_voltage = on;
        if on {
            if self.fsm == fsm::RUN || self.fsm == fsm::ALIGN {
                self.enter_fault(fault::HW_UNDER_VOLTAGE);
            } else {
                self.err_code = fault::HW_UNDER_VOLTAGE;
            }
        } else if self.fsm != fsm::FAULT {
            self.err_code = fault::NONE;
        }
    }

    /// A snapshot for observers.
    pub fn view(&self) -> DeviceView {
        DeviceView {
            slot: self.slot,
            id: self.id,
            fsm: self.fsm,
            err_code: self.err_code,
            mode: self.mode,
            enabled: self.fsm == fsm::RUN || self.fsm == fsm::ALIGN,
            aligned: self.aligned,
            angle_deg: self.angle(),
            target_deg: self.jog_goal.unwrap_or(self.target),
            velocity_deg_s: self.joint.vel,
            spd_ref: self.spd_ref,
            q_current_a: self.joint.current,
            temp_c: self.joint.temp_c,
            vbus_v: if self.under_voltage {
                VBUS_UNDER_V
            } else {
                VBUS_V
            },
            baud: self.baud(),
            silent: self.silent,
            booting: self.booting(self.last),
            jogging: self.jog_goal.is_some(),
            blocked: self.joint.blocked,
            protection_active: self.joint.prot.active,
            bursting: self.joint.prot.bursting(),
            under_voltage: self.under_voltage,
            params: self.ram,
            flash: self.flash,
        }
    }
}

fn q7(deg: f64) -> i16 {
    (deg * Q7)
        .round()
        .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn q15_current(a: f64) -> i16 {
    (a / CURRENT_FULL_SCALE_A * Q15_MAX)
        .round()
        .clamp(-Q15_MAX, Q15_MAX) as i16
}
