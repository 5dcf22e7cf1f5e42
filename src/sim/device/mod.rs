//! One simulated joint module: its state machine and what it does with each
//! command (SPEC §4, §5), driven by timestamps. No I/O: the engine hands it
//! decoded commands and sends what it answers.
//!
//! - this file: state, power-up, time (timed states, jog, faults), the drive it asks of the physics;
//! - [`commands`]: what each command does;
//! - [`report`]: INFO blocks and the observer's view.
//!
//! What the firmware revision changes is asked of its
//! [`Profile`](super::firmware::Profile), never tested here.

mod commands;
mod report;

use std::time::{Duration, Instant};

use crate::protocol::params::index;
use crate::protocol::status::{fault, fsm};
use crate::protocol::units::{current_a, output_deg_per_s, speed_rpm, MAX_ANGLE_DEG, Q15_MAX};
use crate::protocol::{CtrlMode, FirmwareVersion, InfoBlock, Reply};

use super::config::SimConfig;
use super::firmware::{self, AlignLoad, Profile, BRAKE_DONE_DEG_S, OT_RECOVERY_C};
use super::object::Object;
use super::params::{FlashImage, Params};
use super::physics::{Drive, Joint, Obstacle};
use super::rng::Rng;
use super::wire::frame_time;

/// Jog steps (SPEC §4.2).
const JOG_CW_DEG: f64 = 5.0;
const JOG_CCW_DEG: f64 = -3.0;
/// Rotor speed of a jog move, rpm.
const JOG_RPM: f64 = 6000.0;
/// A jog is over when the joint is this close to its goal and this slow.
const JOG_DONE_DEG: f64 = 0.02;
const JOG_DONE_DEG_S: f64 = 0.5;
/// Extra gap between the staggered power-up announcements.
const ANNOUNCE_GAP: Duration = Duration::from_micros(100);

/// Timing the device takes from the simulator's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct DeviceTiming {
    pub align_time: Duration,
    pub boot_delay: Duration,
    pub stall_fault_after: Duration,
    pub soft_ver: u8,
}

/// What handling a command produced.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Outcome {
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
pub(crate) struct Device {
    pub slot: usize,
    pub id: u8,
    pub ram: Params,
    pub flash: Params,
    timing: DeviceTiming,
    profile: Profile,
    fsm: u8,
    /// The active fault (the err_code's low nibble under rev 2.0.8).
    err_code: u8,
    /// The last fault active since power-up (rev 2.0.8's high nibble).
    fault_history: u8,
    aligned: bool,
    /// When the current timed state (init, precharge, align, start, stop) ends.
    timer: Option<Instant>,
    mode: CtrlMode,
    /// Target in reported degrees (after the zero offset).
    target: f64,
    spd_ref: i16,
    /// Current reference (Q15 of 5.625 A): rev 2.0.8 current mode.
    cur_ref: i16,
    /// What INFO_06 reports as the encoder offset under rev 2.0.8.
    enc_offset: u16,
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
    pub(crate) fn new(
        slot: usize,
        image: FlashImage,
        timing: DeviceTiming,
        now: Instant,
        stagger: Duration,
        seed: u64,
        profile: Profile,
    ) -> Self {
        let mut d = Self {
            slot,
            id: image.id,
            ram: image.params,
            flash: image.params,
            timing,
            profile,
            fsm: fsm::READY,
            err_code: fault::NONE,
            fault_history: fault::NONE,
            aligned: false,
            timer: None,
            mode: CtrlMode::Position,
            target: 0.0,
            spd_ref: 0,
            cur_ref: 0,
            enc_offset: firmware::encoder_offset(seed, slot),
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

    /// The devices of a bus powered up at `now`: flash from `saved` by slot,
    /// factory parameters otherwise; each runs the firmware the config gives
    /// its configured id. Announcements are staggered one frame slot apart so
    /// a healthy bus can be discovered from them.
    pub(crate) fn bus(
        cfg: &SimConfig,
        saved: &[FlashImage],
        factory: Params,
        now: Instant,
    ) -> Vec<Self> {
        let timing = DeviceTiming {
            align_time: cfg.align_time,
            boot_delay: cfg.boot_delay,
            stall_fault_after: cfg.stall_fault_after,
            soft_ver: cfg.soft_ver,
        };
        let slot_time = frame_time(cfg.baud) + cfg.turnaround + ANNOUNCE_GAP;
        cfg.ids
            .iter()
            .enumerate()
            .map(|(slot, &id)| {
                let profile = Profile::new(cfg.firmware.revision_of(id));
                let mut image = saved.get(slot).copied().unwrap_or(FlashImage {
                    id,
                    params: factory,
                });
                if profile.knows_index(index::SN) && image.params.raw(index::SN) == 0 {
                    image
                        .params
                        .set_raw(index::SN, firmware::default_serial(cfg.seed, slot));
                }
                let stagger = slot_time * u32::try_from(slot).unwrap_or(u32::MAX);
                let mut device = Self::new(
                    slot,
                    image,
                    timing,
                    now,
                    stagger,
                    cfg.seed ^ slot as u64,
                    profile,
                );
                device.joint.hard_stop = cfg
                    .hard_stops
                    .iter()
                    .find(|(dev_id, _)| *dev_id == id)
                    .map(|(_, deg)| Obstacle::at(*deg));
                device.joint.object = cfg
                    .objects
                    .iter()
                    .find(|o| o.id == id)
                    .map(|o| Object::new(o.at_deg, o.nm_per_deg));
                device
            })
            .collect()
    }

    /// Power-up (or reboot): RAM from flash, ready (rev 2.0.8: after init and
    /// precharge, while it boots), unaligned, position mode, no fault history.
    pub(crate) fn power_up(&mut self, now: Instant, stagger: Duration) {
        self.advance_to(now);
        self.ram = self.flash;
        self.fault_history = fault::NONE;
        self.err_code = fault::NONE;
        if self.under_voltage {
            self.set_active_fault(fault::HW_UNDER_VOLTAGE);
        }
        self.aligned = false;
        self.mode = CtrlMode::Position;
        self.target = self.angle();
        self.spd_ref = 0;
        self.cur_ref = 0;
        self.jog_goal = None;
        self.silent = false;
        self.joint.vel = 0.0;
        self.joint.current = 0.0;
        self.joint.q_loop.reset();
        self.joint.press = None;
        self.joint.prot = Default::default();
        self.boot_until = now + self.timing.boot_delay + stagger;
        self.announce_at = Some(self.boot_until);
        if self.profile.transit_states() {
            self.fsm = fsm::INIT;
            self.timer = Some(now + (self.timing.boot_delay + stagger) / 2);
        } else {
            self.fsm = fsm::READY;
            self.timer = None;
        }
    }

    pub(crate) fn flash_image(&self) -> FlashImage {
        FlashImage {
            id: self.id,
            params: self.flash,
        }
    }

    /// The baud the device listens and talks at.
    pub(crate) fn baud(&self) -> u32 {
        self.ram.baud()
    }

    fn firmware(&self) -> FirmwareVersion {
        FirmwareVersion(self.timing.soft_ver)
    }

    /// Reported output angle, degrees.
    pub(crate) fn angle(&self) -> f64 {
        self.joint.pos - self.zero
    }

    fn booting(&self, now: Instant) -> bool {
        now < self.boot_until
    }

    /// When the spontaneous power-up INFO_01 is due.
    pub(crate) fn announce_at(&self) -> Option<Instant> {
        self.announce_at
    }

    /// The power-up INFO_01, once it is due.
    pub(crate) fn take_announcement(&mut self, now: Instant) -> Option<Reply> {
        let due = self.announce_at.filter(|t| *t <= now)?;
        self.announce_at = None;
        self.advance_to(due);
        Some(self.info(InfoBlock::Info01))
    }

    /// Runs the physics and timers up to `now`.
    pub(crate) fn advance_to(&mut self, now: Instant) {
        self.run_due_timers();
        while self.last < now {
            let edge = self
                .timer
                .filter(|t| *t > self.last && *t <= now)
                .unwrap_or(now);
            let dt = (edge - self.last).as_secs_f64();
            let drive = self.drive();
            let bounds = (self.zero - MAX_ANGLE_DEG, self.zero + MAX_ANGLE_DEG);
            self.joint.advance(dt, drive, &self.ram, bounds);
            self.last = edge;
            self.run_due_timers();
        }
        self.check_brake();
        self.check_jog();
        self.check_faults();
    }

    /// Leaves every timed state whose time is up (one may start the next).
    fn run_due_timers(&mut self) {
        while let Some(at) = self.timer.filter(|t| *t <= self.last) {
            self.timer = None;
            self.timer_done(at);
        }
    }

    fn timer_done(&mut self, at: Instant) {
        match self.fsm {
            fsm::INIT => {
                self.fsm = fsm::PRECHARGE;
                self.timer = Some(self.boot_until);
            }
            fsm::PRECHARGE | fsm::STOP => self.fsm = fsm::READY,
            fsm::ALIGN => {
                self.aligned = true;
                self.target = self.angle();
                self.start(at);
            }
            fsm::START => self.fsm = fsm::RUN,
            _ => {}
        }
    }

    /// Powered and aligned: run, through start under rev 2.0.8.
    fn start(&mut self, at: Instant) {
        if self.profile.transit_states() {
            self.fsm = fsm::START;
            self.timer = Some(at + firmware::START_TIME);
        } else {
            self.fsm = fsm::RUN;
        }
    }

    /// Rev 2.0.8 brake ends once the joint has (nearly) stopped: then stop.
    fn check_brake(&mut self) {
        if self.fsm == fsm::BRAKE && self.joint.vel.abs() < BRAKE_DONE_DEG_S {
            self.fsm = fsm::STOP;
            self.timer = Some(self.last + firmware::STOP_TIME);
        }
    }

    /// The motor is powered (align, start, run): what "enabled" means.
    pub(crate) fn enabled(&self) -> bool {
        matches!(self.fsm, fsm::ALIGN | fsm::START | fsm::RUN)
    }

    /// What an alignment starting now carries.
    fn align_load(&self) -> AlignLoad {
        match self.joint.obstacle {
            None => AlignLoad::Free,
            Some(ob) if (self.joint.pos - ob.at).abs() < 1e-6 || self.joint.blocked => {
                AlignLoad::Pressed
            }
            Some(_) => AlignLoad::Obstacle,
        }
    }

    /// err_code as the wire carries it.
    pub(crate) fn err_byte(&self) -> u8 {
        self.profile.err_byte(self.err_code, self.fault_history)
    }

    /// A fault becomes active (and, under rev 2.0.8, the latched history).
    fn set_active_fault(&mut self, code: u8) {
        self.err_code = code;
        if code != fault::NONE {
            self.fault_history = code;
        }
    }

    fn drive(&self) -> Drive {
        if self.fsm == fsm::BRAKE {
            return Drive::Speed { vel: 0.0 };
        }
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
        let rpm = self.speed_rpm();
        match self.mode {
            CtrlMode::Position => Drive::Position {
                target: self.target + self.zero,
                vmax: output_deg_per_s(rpm.abs()),
            },
            CtrlMode::Speed => Drive::Speed {
                vel: output_deg_per_s(rpm),
            },
            CtrlMode::Current => Drive::Current {
                amps: current_a(self.cur_ref),
            },
            CtrlMode::None => Drive::Off,
        }
    }

    /// The rotor speed the reference asks for: as sent under V2.0.1; under
    /// rev 2.0.8 capped by SPD_LIMIT, and 0 in position mode means the limit.
    fn speed_rpm(&self) -> f64 {
        let rpm = self.rpm_of(self.spd_ref);
        if !self.profile.uses_speed_limit() {
            return rpm;
        }
        let raw = self.ram.raw(index::SPD_LIMIT).min(Q15_MAX as u16);
        let limit = self.rpm_of(i16::try_from(raw).unwrap_or(i16::MAX)).abs();
        if self.mode == CtrlMode::Position && self.spd_ref == 0 {
            limit
        } else {
            rpm.clamp(-limit, limit)
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
        if self.err_code == fault::OVER_TEMPERATURE && self.cooled_down() {
            self.err_code = fault::NONE;
            if self.fsm == fsm::FAULT {
                self.fsm = fsm::READY;
            }
        }
        if self.fsm != fsm::RUN {
            return;
        }
        if self.joint.blocked_s >= self.timing.stall_fault_after.as_secs_f64() {
            self.enter_fault(fault::STALL);
        } else if self.joint.temp_c > self.profile.drv_ot_c(&self.ram) {
            self.enter_fault(fault::OVER_TEMPERATURE);
        }
    }

    /// Rev 2.0.8: an over-temperature clears 10 °C below the threshold
    /// (V2.0.1: never by itself; a disable clears it).
    fn cooled_down(&self) -> bool {
        self.profile.ot_recovers()
            && self.joint.temp_c <= self.profile.drv_ot_c(&self.ram) - OT_RECOVERY_C
    }

    fn enter_fault(&mut self, code: u8) {
        self.fsm = fsm::FAULT;
        self.set_active_fault(code);
        self.jog_goal = None;
        self.timer = None;
    }

    fn rezero(&mut self) {
        self.zero = self.joint.pos;
        self.target = 0.0;
    }

    // ---- fault injection ----

    /// Puts an obstacle at `at_deg` (reported degrees), or right where the joint is.
    pub(crate) fn set_obstacle(&mut self, at_deg: Option<f64>, now: Instant) {
        self.advance_to(now);
        let at = at_deg.map_or(self.joint.pos, |a| a + self.zero);
        self.joint.obstacle = Some(Obstacle::at(at));
    }

    pub(crate) fn clear_obstacle(&mut self, now: Instant) {
        self.advance_to(now);
        self.joint.obstacle = None;
        self.joint.blocked_s = 0.0;
    }

    /// Puts an elastic object at `at_deg` (reported degrees).
    pub(crate) fn set_object(&mut self, at_deg: f64, nm_per_deg: f64, now: Instant) {
        self.advance_to(now);
        self.joint.object = Some(Object::new(at_deg + self.zero, nm_per_deg));
    }

    /// Pulls the object away: nothing resists the joint any more.
    pub(crate) fn remove_object(&mut self, now: Instant) {
        self.advance_to(now);
        self.joint.object = None;
    }

    pub(crate) fn set_under_voltage(&mut self, on: bool, now: Instant) {
        self.advance_to(now);
        self.under_voltage = on;
        if on {
            if self.enabled() {
                self.enter_fault(fault::HW_UNDER_VOLTAGE);
            } else {
                self.set_active_fault(fault::HW_UNDER_VOLTAGE);
            }
        } else if self.fsm != fsm::FAULT && self.err_code == fault::HW_UNDER_VOLTAGE {
            self.err_code = fault::NONE;
        }
    }
}
