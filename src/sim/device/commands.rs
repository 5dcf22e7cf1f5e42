//! What a device does with each command it hears (SPEC §4), as its
//! firmware profile says.

use std::time::{Duration, Instant};

use crate::protocol::command::{index, WRITE_FLASH_KEY};
use crate::protocol::reply::{RES_FAILURE, RES_SUCCESS};
use crate::protocol::status::{fault, fsm};
use crate::protocol::units::{angle_deg, MAX_ANGLE_DEG};
use crate::protocol::{
    BroadcastEnable, Command, Config, ConfigParam, Control, ControlOp, CtrlMode, Group, JogDir,
    Reply, ReplyBody, VendorCommand, ALL_DEVICES,
};

use super::super::firmware;
use super::{Device, Outcome, JOG_CCW_DEG, JOG_CW_DEG};

impl Device {
    /// Handles one command heard on the line at `now`.
    pub(crate) fn handle(&mut self, cmd: &Command, now: Instant) -> Outcome {
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
            Command::Vendor(VendorCommand::EnableAll { dev_id, op })
                if self.profile.vendor_enable_all() && self.addressed(*dev_id) =>
            {
                // The SDK sends 0 for "disable"; 2 is the control frame's disable.
                match op {
                    1 => self.enable(now),
                    0 | 2 => self.disable(),
                    _ => {}
                }
            }
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
            ControlOp::SetRef => self.set_ref(Some(c.pos_ref), Some(c.spd_ref), Some(c.cur_ref)),
            // SET_REF under rev 2.0.8, a no-op in V2.0.1 (SPEC §4.1, errata 10).
            ControlOp::SetRefRev208 if self.profile.en_zero_sets_ref() => {
                self.set_ref(Some(c.pos_ref), Some(c.spd_ref), Some(c.cur_ref))
            }
            ControlOp::SetRefRev208 => {}
        }
    }

    fn enable(&mut self, now: Instant) {
        if self.fsm != fsm::READY {
            return;
        }
        // A cause still present faults again (rev 2.0.8 keeps an
        // over-temperature active until the joint has cooled).
        if self.under_voltage {
            self.enter_fault(fault::HW_UNDER_VOLTAGE);
            return;
        }
        if self.err_code == fault::OVER_TEMPERATURE {
            self.enter_fault(fault::OVER_TEMPERATURE);
            return;
        }
        self.target = self.angle();
        self.cur_ref = 0;
        if self.aligned {
            self.start(now);
        } else {
            self.fsm = fsm::ALIGN;
            let align = self
                .profile
                .align_time(self.timing.align_time, self.align_load());
            self.timer = Some(now + align);
        }
    }

    /// Release: ready (rev 2.0.8: through brake if still turning, then
    /// stop). Clears a fault whose cause is gone.
    fn disable(&mut self) {
        let was = self.fsm;
        self.timer = None;
        self.jog_goal = None;
        let still = if self.under_voltage {
            fault::HW_UNDER_VOLTAGE
        } else if self.err_code == fault::OVER_TEMPERATURE && self.profile.ot_recovers() {
            fault::OVER_TEMPERATURE
        } else {
            fault::NONE
        };
        self.set_active_fault(still);
        if !self.profile.transit_states() {
            self.fsm = fsm::READY;
        } else if matches!(was, fsm::READY | fsm::BRAKE) {
            self.fsm = was;
        } else if self.joint.vel.abs() >= firmware::BRAKE_DONE_DEG_S {
            self.fsm = fsm::BRAKE;
        } else {
            self.fsm = fsm::STOP;
            self.timer = Some(self.last + firmware::STOP_TIME);
        }
    }

    /// New references (SET_REF or a broadcast). In speed mode the angle is ignored.
    fn set_ref(&mut self, pos_ref: Option<i16>, spd_ref: Option<i16>, cur_ref: Option<i16>) {
        if let Some(p) = pos_ref.filter(|_| self.mode != CtrlMode::Speed) {
            self.target = angle_deg(p).clamp(-MAX_ANGLE_DEG, MAX_ANGLE_DEG);
            self.jog_goal = None;
        }
        if let Some(s) = spd_ref {
            self.spd_ref = s;
        }
        if let Some(c) = cur_ref {
            self.cur_ref = c;
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
            self.set_ref(Some(v), None, None);
        } else {
            self.set_ref(None, Some(v), None);
        }
    }

    /// `0xB155` in the table layout (SPEC errata 3: unverified): one byte per
    /// device 1..16, with the control frame's EN codes. Its CRC over bytes
    /// 0..18 (E1_Hand_G474's reading) is obeyed by rev 2.0.8 firmware only.
    fn broadcast_enable(&mut self, b: &BroadcastEnable, now: Instant) {
        if !self.profile.accepts_enable_broadcast(b.crc) {
            return;
        }
        let Some(op) = usize::from(self.id)
            .checked_sub(1)
            .and_then(|i| b.ops.get(i))
        else {
            return;
        };
        if *op == ControlOp::Enable as u8 {
            self.enable(now);
        } else if *op == ControlOp::Disable as u8 {
            self.disable();
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
        // An index the firmware's revision does not have is ignored: no
        // reply (how a host tells a V2.0.1 device by an INFO_07 read).
        if !self.profile.knows_index(c.param.index_value().0) {
            return Outcome::default();
        }
        if let ConfigParam::ReadInfo(block) = c.param {
            // Reads cannot be broadcast (SPEC §4.3): only the exact id answers.
            return if c.dev_id == self.id {
                Outcome::reply(self.info(block))
            } else {
                Outcome::default()
            };
        }
        // A write to 0xFF reaches every device, and each answers as for its
        // own id: replies to such a write collide (see `firmware`).
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
                // SPEC documents the RES from rev 2.0.8 on; V2.0.1 answers nothing.
                if self.profile.enc_zero_replies() {
                    return Outcome::reply(self.res(index::UPDATE_ENC_ZERO, idle));
                }
            }
            ConfigParam::CommSilent(v) => self.silent = v != 0,
            ConfigParam::CtrlMode(m) => self.switch_mode(m),
            ConfigParam::WriteFlash { key } => return self.write_flash(key),
            ConfigParam::ReadFlash => self.ram = self.flash,
            ConfigParam::BaudRate(level) => {
                // The RES goes out at the old baud (the engine times it by the
                // request); from now on the device listens at the new one.
                self.ram.apply(&ConfigParam::BaudRate(level));
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
        // Mode 3 is rev 2.0.8's; V2.0.1 firmware ignores it.
        if m == CtrlMode::Current && !self.profile.current_mode() {
            return;
        }
        self.mode = m;
        self.jog_goal = None;
        self.target = self.angle();
        match m {
            CtrlMode::Speed => self.spd_ref = 0,
            CtrlMode::Current => self.cur_ref = 0,
            _ => {}
        }
    }
}
