//! One-shot requests: what each does on the wire and how it is confirmed.
//!
//! - Enable/disable use standard control frames (SPEC errata 3) and are
//!   confirmed by the fsm in a fresh INFO_01.
//! - Config writes are confirmed by RES or by reading the INFO block back
//!   (see [`super::verify`]); a mismatch is an error to the caller.
//! - An id change moves the registry entry and the setpoint slot; a baud
//!   change switches every device first, then the port.

use crate::protocol::command::index;
use crate::protocol::reply::{fault_name, fsm, fsm_name, RES_SUCCESS};
use crate::protocol::{
    is_device_id, Command, Config, ConfigParam, Control, CtrlMode, Info01, InfoBlock, Jog, JogDir,
    Reply, ReplyBody, ALL_DEVICES,
};

use super::error::BusError;
use super::handle::{BusEvent, Request, Targets, WriteOutcome};
use super::link::Want;
use super::owner::Owner;
use super::schedule::describe;
use super::verify::{confirmation, Confirm};

/// INFO_01 reads that may pass before an enable/disable shows in the fsm.
const FSM_CHECKS: u32 = 3;
/// How close to 0° a re-zeroed angle must read when the joint stands still.
const REZERO_TOLERANCE_DEG: f64 = 0.5;
/// Fastest a joint's output turns (50000 rpm rotor through the gearbox,
/// ~527 °/s): a joint moving while it is re-zeroed has left 0° by the time
/// the read-back answers, by at most this speed times the time between.
const MAX_OUTPUT_DEG_PER_S: f64 = 50_000.0 * 6.0 / crate::protocol::units::GEAR_RATIO;

/// How far from 0° a joint re-zeroed `elapsed` before the read-back may be.
fn rezero_tolerance_deg(elapsed: std::time::Duration) -> f64 {
    REZERO_TOLERANCE_DEG + MAX_OUTPUT_DEG_PER_S * elapsed.as_secs_f64()
}

/// Answers a request with `err` without running it (bus down, e-stop, stop).
pub(super) fn fail(req: Request, err: BusError) {
    // A caller that gave up has dropped its receiver: nothing to tell.
    match req {
        Request::Enable { reply, .. }
        | Request::Disable { reply, .. }
        | Request::Jog { reply, .. }
        | Request::Rezero { reply, .. }
        | Request::SetMode { reply, .. }
        | Request::SetBaud { reply, .. } => drop(reply.send(Err(err))),
        Request::ReadInfo { reply, .. } => drop(reply.send(Err(err))),
        Request::WriteConfig { reply, .. }
        | Request::WriteFlash { reply, .. }
        | Request::SetId { reply, .. } => drop(reply.send(Err(err))),
        Request::Scan { reply, .. } => drop(reply.send(Err(err))),
    }
}

impl Owner {
    pub(super) fn run_request(&mut self, req: Request) {
        match req {
            Request::Enable { targets, reply } => drop(reply.send(self.enable(targets))),
            Request::Disable { targets, reply } => drop(reply.send(self.disable(targets))),
            Request::Jog { dev_id, dir, reply } => drop(reply.send(self.jog(dev_id, dir))),
            Request::Rezero { dev_id, reply } => drop(reply.send(self.rezero(dev_id))),
            Request::SetMode {
                dev_id,
                mode,
                reply,
            } => drop(reply.send(self.set_mode(dev_id, mode))),
            Request::ReadInfo {
                dev_id,
                block,
                reply,
            } => drop(reply.send(self.read_info(dev_id, block))),
            Request::WriteConfig {
                dev_id,
                param,
                reply,
            } => drop(reply.send(self.write_config(dev_id, param))),
            Request::WriteFlash { dev_id, reply } => {
                let key = crate::protocol::command::WRITE_FLASH_KEY;
                drop(reply.send(self.write_config(dev_id, ConfigParam::WriteFlash { key })))
            }
            Request::SetId {
                dev_id,
                new_id,
                reply,
            } => drop(reply.send(self.set_id(dev_id, new_id))),
            Request::SetBaud { baud, reply } => drop(reply.send(self.set_baud(baud))),
            Request::Scan { first, last, reply } => drop(reply.send(self.scan(first, last))),
        }
    }

    pub(super) fn known(&self, id: u8) -> Result<(), BusError> {
        match self.sched.registry().get(id) {
            Some(_) => Ok(()),
            None => Err(BusError::UnknownDevice {
                bus: self.cfg.name.clone(),
                dev_id: id,
            }),
        }
    }

    /// The ids a control request addresses, each known.
    fn resolve(&self, targets: &Targets) -> Result<Vec<u8>, BusError> {
        match targets {
            Targets::All => Ok(self.sched.registry().online_ids()),
            Targets::Ids(ids) => {
                ids.iter().try_for_each(|id| self.known(*id))?;
                Ok(ids.clone())
            }
        }
    }

    /// Control frames for `op` to `targets`: one `0xFF` frame for all.
    fn control_frames(targets: &Targets, ids: &[u8], make: fn(u8) -> Control) -> Vec<Command> {
        match targets {
            Targets::All => vec![Command::Control(make(ALL_DEVICES))],
            Targets::Ids(_) => ids.iter().map(|id| Command::Control(make(*id))).collect(),
        }
    }

    fn enable(&mut self, targets: Targets) -> Result<(), BusError> {
        let ids = self.resolve(&targets)?;
        self.job_send(&Self::control_frames(&targets, &ids, Control::enable))?;
        for &id in &ids {
            // It holds where it is; a target set before the enable goes out again.
            self.sched.registry_mut().forget_target(id);
            if let Some(setpoint) = self.shared.setpoints.get(id) {
                self.sched.requeue(id, setpoint);
            }
        }
        for &id in &ids {
            self.await_fsm(id, "enable", |f| f == fsm::ALIGN || f == fsm::RUN)?;
        }
        Ok(())
    }

    fn disable(&mut self, targets: Targets) -> Result<(), BusError> {
        let ids = self.resolve(&targets)?;
        self.job_send(&Self::control_frames(&targets, &ids, Control::disable))?;
        // `0xFF` reached offline devices too: every target goes.
        let cleared = match targets {
            Targets::All => self.sched.registry().ids(),
            Targets::Ids(_) => ids.clone(),
        };
        self.shared.setpoints.clear(Some(&cleared));
        for &id in &cleared {
            self.sched.forget_setpoint(id);
            self.sched.registry_mut().forget_target(id);
        }
        for &id in &ids {
            self.await_fsm(id, "disable", |f| f == fsm::READY || f == fsm::FAULT)?;
        }
        Ok(())
    }

    /// Reads INFO_01 until the fsm satisfies `ok`; a fault is reported by name.
    fn await_fsm(&mut self, id: u8, what: &str, ok: fn(u8) -> bool) -> Result<Info01, BusError> {
        let mut last = None;
        for _ in 0..FSM_CHECKS {
            let info = self.read_info01(id)?;
            if ok(info.fsm) {
                return Ok(info);
            }
            if info.fsm == fsm::FAULT {
                return Err(BusError::WrongState(format!(
                    "device {id} is in fault: {}",
                    fault_name(info.err_code & 0x0F)
                )));
            }
            last = Some(info.fsm);
        }
        Err(BusError::WrongState(format!(
            "device {id} did not {what}: its state is {}",
            last.map_or("unknown", fsm_name)
        )))
    }

    pub(super) fn read_info01(&mut self, id: u8) -> Result<Info01, BusError> {
        match self.read_info(id, InfoBlock::Info01)?.body() {
            ReplyBody::Info01(info) => Ok(info),
            _ => Err(BusError::Invalid(
                "INFO_01 read returned another block".into(),
            )),
        }
    }

    fn jog(&mut self, dev_id: u8, dir: JogDir) -> Result<(), BusError> {
        self.known(dev_id)?;
        let info = self.read_info01(dev_id)?;
        if info.fsm != fsm::RUN {
            return Err(BusError::WrongState(format!(
                "jog needs an enabled joint; device {dev_id} is {}",
                fsm_name(info.fsm)
            )));
        }
        self.job_send(&[Command::Jog(Jog { dev_id, dir })])?;
        self.zero_moved(dev_id);
        Ok(())
    }

    fn rezero(&mut self, dev_id: u8) -> Result<(), BusError> {
        self.known(dev_id)?;
        let cmd = Config {
            dev_id,
            param: ConfigParam::UpdateFinZero,
        };
        self.job_send(&[Command::Config(cmd)])?;
        // Handed to the port now, on the wire a little later: measuring from
        // here bounds the joint's travel since from above.
        let sent = std::time::Instant::now();
        self.zero_moved(dev_id);
        let angle = self.read_info01(dev_id)?.angle;
        let within =
            crate::protocol::units::angle_deg(angle).abs() <= rezero_tolerance_deg(sent.elapsed());
        if !within {
            return Err(BusError::VerifyMismatch {
                dev_id,
                index: index::UPDATE_FIN_ZERO,
                expected: 0,
                found: angle as u16,
            });
        }
        Ok(())
    }

    /// The device's zero moved: targets and angles from before are void.
    fn zero_moved(&mut self, id: u8) {
        self.sched.registry_mut().zero_moved(id);
        self.shared.setpoints.clear(Some(&[id]));
        self.sched.forget_setpoint(id);
    }

    fn set_mode(&mut self, dev_id: u8, mode: CtrlMode) -> Result<(), BusError> {
        self.write_config(dev_id, ConfigParam::CtrlMode(mode))
            .map(|_| ())
    }

    pub(super) fn read_info(&mut self, dev_id: u8, block: InfoBlock) -> Result<Reply, BusError> {
        self.known(dev_id)?;
        let want = Want {
            dev_id,
            index: block.index(),
        };
        self.transact(Config::read(dev_id, block), want)
    }

    fn write_config(&mut self, dev_id: u8, param: ConfigParam) -> Result<WriteOutcome, BusError> {
        self.known(dev_id)?;
        let how = confirmation(&param).map_err(|why| BusError::Invalid(why.to_string()))?;
        let (idx, value) = param.index_value();
        let cmd = Config { dev_id, param };
        let verified_by = match how {
            Confirm::Res => {
                let reply = self.transact(cmd, Want { dev_id, index: idx })?;
                check_res(&reply, &param)?;
                "res"
            }
            Confirm::ReadBack { block, field } => {
                self.job_send(&[Command::Config(cmd)])?;
                let found = field(&self.read_info(dev_id, block)?.data);
                if found != value {
                    return Err(BusError::VerifyMismatch {
                        dev_id,
                        index: idx,
                        expected: value,
                        found,
                    });
                }
                "read_back"
            }
            Confirm::Unverifiable => {
                self.job_send(&[Command::Config(cmd)])?;
                self.after_unverifiable(dev_id, &param);
                "unverifiable"
            }
        };
        Ok(WriteOutcome {
            dev_id,
            index: idx,
            value,
            verified_by,
        })
    }

    fn after_unverifiable(&mut self, dev_id: u8, param: &ConfigParam) {
        match param {
            ConfigParam::CtrlMode(mode) => {
                self.sched.registry_mut().set_mode(dev_id, *mode);
                self.shared.setpoints.clear(Some(&[dev_id]));
                self.sched.forget_setpoint(dev_id);
            }
            ConfigParam::UpdateFinZero => self.zero_moved(dev_id),
            _ => {}
        }
    }

    fn set_id(&mut self, dev_id: u8, new_id: u8) -> Result<WriteOutcome, BusError> {
        self.known(dev_id)?;
        if !is_device_id(new_id) || new_id == dev_id {
            return Err(BusError::Invalid(format!(
                "new id {new_id} must be in 1..=159 and differ from {dev_id}"
            )));
        }
        if self.sched.registry().get(new_id).is_some() {
            return Err(BusError::WrongState(format!(
                "id {new_id} is already taken on bus {}",
                self.cfg.name
            )));
        }
        let param = ConfigParam::SetId { new_id };
        let cmd = Config { dev_id, param };
        // No retry to the old id: the device may have changed and its RES got lost.
        let want = Want {
            dev_id: new_id,
            index: index::SET_ID,
        };
        let verified_by = match self.try_transact(cmd, want, 1)? {
            Some(reply) => {
                check_res(&reply, &param)?;
                "res"
            }
            None => self.confirm_new_id(dev_id, new_id, &param)?,
        };
        self.rename(dev_id, new_id);
        Ok(WriteOutcome {
            dev_id: new_id,
            index: index::SET_ID,
            value: param.index_value().1,
            verified_by,
        })
    }

    /// The RES of an id change did not come: does the new id answer?
    fn confirm_new_id(
        &mut self,
        dev_id: u8,
        new_id: u8,
        param: &ConfigParam,
    ) -> Result<&'static str, BusError> {
        let read = Config::read(new_id, InfoBlock::Info01);
        let want = Want {
            dev_id: new_id,
            index: index::INFO_01_R,
        };
        match self.try_transact(read, want, 1 + self.cfg.timing.retries)? {
            Some(_) => Ok("read_back"),
            None => Err(self.timeout_error(dev_id, param, 1)),
        }
    }

    /// The registry entry and the setpoint slot follow the device. An entry
    /// the read-back made for the new id is replaced by the old one's history.
    fn rename(&mut self, old: u8, new: u8) {
        self.sched.rename(old, new);
        self.shared.setpoints.rename(old, new);
        self.sched.push_event(BusEvent::IdChanged {
            bus: self.cfg.name.clone(),
            old,
            new,
        });
    }
}

/// Checks a RES reply: 1 is success.
pub(super) fn check_res(reply: &Reply, param: &ConfigParam) -> Result<(), BusError> {
    match reply.body() {
        ReplyBody::Res { code, .. } if code == RES_SUCCESS => Ok(()),
        ReplyBody::Res { code, .. } => Err(BusError::Refused {
            dev_id: reply.dev_id,
            what: describe(param),
            code,
        }),
        _ => Err(BusError::Invalid(format!(
            "device {} answered {} with index {} instead of RES",
            reply.dev_id,
            describe(param),
            reply.index
        ))),
    }
}
