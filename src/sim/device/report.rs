//! What a device reports: INFO blocks from its state (SPEC §5, §6 units),
//! with plausible sensor noise, and the observer's [`DeviceView`].

use crate::protocol::reply::{fsm, Info01, Info02};
use crate::protocol::units::{GEAR_RATIO, Q15_MAX};
use crate::protocol::{InfoBlock, Reply, ReplyBody};

use super::super::view::DeviceView;
use super::Device;

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

impl Device {
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
            zero_deg: self.zero,
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
