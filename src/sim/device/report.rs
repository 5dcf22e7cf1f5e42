//! What a device reports: INFO blocks from its state (SPEC §5), with
//! plausible sensor noise, and the observer's [`DeviceView`]. Physical →
//! raw goes through [`crate::protocol::units`]; the parameter blocks
//! (INFO_03..06) are laid out by the parameter table ([`Params::block`]).
//!
//! [`Params::block`]: super::super::params::Params::block

use crate::protocol::params::index;
use crate::protocol::reply::{Info01, Info02};
use crate::protocol::status::fsm;
use crate::protocol::units;
use crate::protocol::{InfoBlock, Reply, ReplyBody};

use super::super::view::DeviceView;
use super::Device;

/// Bus voltage: nominal, sag per ampere, noise, and under-voltage level.
const VBUS_V: f64 = 12.0;
const VBUS_SAG_V_PER_A: f64 = 0.3;
const VBUS_NOISE_V: f64 = 0.02;
const VBUS_UNDER_V: f64 = 6.0;
/// Measurement noise on the reported d and q currents, A (standard
/// deviation, normally distributed, independent per report). Model
/// assumption: a small FOC drive measures phase currents with a 12-bit
/// ADC over about ±5.6 A (the Q15 full scale of 5.625 A), 2.7 mA a
/// count; a few counts of noise after the Park transform, ≈ 1.5 counts rms.
const CURRENT_NOISE_A: f64 = 0.004;
/// Encoder noise on reported angles, degrees.
const ANGLE_NOISE_DEG: f64 = 0.004;

impl Device {
    /// The INFO block a read asks for, from the current state.
    pub(crate) fn info(&mut self, block: InfoBlock) -> Reply {
        let body = match block {
            InfoBlock::Info01 => ReplyBody::Info01(self.info01()),
            InfoBlock::Info02 => ReplyBody::Info02(self.info02()),
            InfoBlock::Info07 => {
                // Rev 2.0.8 only (the device checks before asking). The layout
                // is unpublished: the simulator puts SN's u16 first.
                let mut sn = [0u8; 8];
                sn[..2].copy_from_slice(&self.ram.raw(index::SN).to_le_bytes());
                ReplyBody::Info07(sn)
            }
            parameters => {
                let mut data = self.ram.block(parameters);
                if parameters == InfoBlock::Info06 {
                    self.profile.info06_tail(
                        &mut data,
                        self.enc_offset,
                        self.ram.raw(index::DRV_OT),
                        self.ram.raw(index::SPD_LIMIT),
                    );
                }
                return Reply {
                    dev_id: self.id,
                    index: parameters.index(),
                    data,
                };
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
            err_code: self.err_byte(),
            soft_ver: self.timing.soft_ver,
            temp_raw: units::temp_raw_saturating(self.joint.temp_c),
            angle: units::angle_raw_saturating(angle),
            vbus: units::volts_raw_saturating(self.vbus()),
        }
    }

    fn info02(&mut self) -> Info02 {
        let rotor_rpm = units::rotor_rpm(self.joint.vel);
        let powered = self.enabled() || self.fsm == fsm::BRAKE;
        let noise = if powered { CURRENT_NOISE_A } else { 0.0 };
        let d = self.rng.gauss(noise);
        let q = self.joint.q_loop.amps + self.rng.gauss(noise);
        Info02 {
            d_cur: units::current_raw_saturating(d),
            q_cur: units::current_raw_saturating(q),
            speed: units::speed_raw_saturating(rotor_rpm, self.firmware()),
            angle: units::angle_raw_saturating(self.angle() + self.rng.noise(ANGLE_NOISE_DEG)),
        }
    }

    /// A snapshot for observers.
    pub(crate) fn view(&self) -> DeviceView {
        DeviceView {
            slot: self.slot,
            id: self.id,
            firmware: self.profile.revision(),
            fsm: self.fsm,
            err_code: self.err_byte(),
            mode: self.mode,
            enabled: self.enabled(),
            aligned: self.aligned,
            angle_deg: self.angle(),
            zero_deg: self.zero,
            target_deg: self.jog_goal.unwrap_or(self.target),
            velocity_deg_s: self.joint.vel,
            spd_ref: self.spd_ref,
            cur_ref: self.cur_ref,
            q_current_a: self.joint.q_loop.amps,
            q_current_ref_a: self.joint.current,
            object_push_a: self
                .joint
                .object
                .map_or(0.0, |o| o.push_a(self.joint.pos).abs()),
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
