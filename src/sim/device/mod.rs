//! One simulated joint module: its state machine and what it does with each
//! command (SPEC §4, §5), driven by timestamps. No I/O: the engine hands it
//! decoded commands and sends what it answers.
//!
//! - this file: state, power-up, time (align, jog, faults), the drive it asks of the physics;
//! - [`commands`]: what each command does;
//! - [`report`]: INFO blocks and the observer's view.

mod commands;
mod report;

use std::time::{Duration, Instant};

use crate::protocol::params::index;
use crate::protocol::status::{fault, fsm};
use crate::protocol::units::{output_deg_per_s, speed_rpm, MAX_ANGLE_DEG, Q15_MAX};
use crate::protocol::{CtrlMode, FirmwareVersion, InfoBlock, Reply};

use super::config::SimConfig;
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
    pub(crate) fn new(
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

    /// The devices of a bus powered up at `now`: flash from `saved` by slot,
    /// factory parameters otherwise. Announcements are staggered one frame slot
    /// apart so a healthy bus can be discovered from them.
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
        let images = cfg.ids.iter().enumerate().map(|(slot, &id)| {
            saved.get(slot).copied().unwrap_or(FlashImage {
                id,
                params: factory,
            })
        });
        images
            .enumerate()
            .map(|(slot, image)| {
                let stagger = slot_time * u32::try_from(slot).unwrap_or(u32::MAX);
                Self::new(slot, image, timing, now, stagger, cfg.seed ^ slot as u64)
            })
            .collect()
    }

    /// Power-up (or reboot): RAM from flash, ready, unaligned, position mode.
    pub(crate) fn power_up(&mut self, now: Instant, stagger: Duration) {
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
            .rpm_of(self.ram.raw(index::SPD_LIMIT).min(Q15_MAX as u16) as i16)
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
        } else if self.joint.temp_c > self.ram.physical(index::DRV_OT) {
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

    pub(crate) fn set_under_voltage(&mut self, on: bool, now: Instant) {
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
}
