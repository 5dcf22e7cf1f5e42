//! A bus-wide baud change (SPEC §4.3 index 15): every online device is
//! switched first (each answers RES at the old baud, then listens only at
//! the new one), then the port; each device is then read back at the new
//! baud. If a device refuses, the ones already switched are switched back.

use crate::protocol::command::index;
use crate::protocol::{BaudLevel, Config, ConfigParam, Info04, InfoBlock};

use super::error::BusError;
use super::handle::BusEvent;
use super::jobs::check_res;
use super::link::Want;
use super::owner::Owner;

impl Owner {
    pub(super) fn set_baud(&mut self, baud: u32) -> Result<(), BusError> {
        let level = BaudLevel::from_baud(baud).ok_or_else(|| {
            BusError::Invalid(format!(
                "baud {baud} is not one of 500000, 230400, 115200, 38400, 19200"
            ))
        })?;
        let old = self.link.baud();
        if baud == old {
            return Ok(());
        }
        let old_level = BaudLevel::from_baud(old)
            .ok_or_else(|| BusError::Invalid(format!("the port runs at {old}, not a SPEC baud")))?;
        let ids = self.sched.registry().online_ids();
        if ids.is_empty() {
            return Err(BusError::WrongState(format!(
                "no device is online on bus {} to change its baud",
                self.cfg.name
            )));
        }
        // Until every device and the port agree, an e-stop would not reach
        // all of them: this phase (a few ms) runs to its end, then the e-stop.
        self.sched.set_exclusive(true);
        let switched = self.switch_all(&ids, level, old_level, baud, old);
        self.sched.set_exclusive(false);
        switched?;
        self.confirm_level(&ids, level)?;
        self.sched.push_event(BusEvent::BaudChanged {
            bus: self.cfg.name.clone(),
            baud,
        });
        Ok(())
    }

    /// Each device, then the port; on a refusal the switched ones go back.
    fn switch_all(
        &mut self,
        ids: &[u8],
        level: BaudLevel,
        old_level: BaudLevel,
        baud: u32,
        old: u32,
    ) -> Result<(), BusError> {
        let mut touched = Vec::new();
        for &id in ids {
            let result = self.switch_device(id, level);
            // A timed-out device may have switched with its RES lost.
            if result.is_ok() || matches!(result, Err(BusError::Timeout { .. })) {
                touched.push(id);
            }
            if let Err(e) = result {
                self.switch_back(&touched, old_level, baud, old);
                return Err(e);
            }
        }
        self.switch_port(baud)
    }

    /// Every device answers at the new baud and reports the new level.
    fn confirm_level(&mut self, ids: &[u8], level: BaudLevel) -> Result<(), BusError> {
        for &id in ids {
            let info = Info04::from_bytes(&self.read_info(id, InfoBlock::Info04)?.data);
            if info.baud_level != level as u8 {
                return Err(BusError::VerifyMismatch {
                    dev_id: id,
                    index: index::BAUD_RATE,
                    expected: level as u16,
                    found: u16::from(info.baud_level),
                });
            }
        }
        Ok(())
    }

    /// One device to `level`; no retry (a retry at the old baud would go
    /// unheard if the first attempt switched it).
    fn switch_device(&mut self, id: u8, level: BaudLevel) -> Result<(), BusError> {
        let param = ConfigParam::BaudRate(level);
        let want = Want {
            dev_id: id,
            index: index::BAUD_RATE,
        };
        match self.try_transact(Config { dev_id: id, param }, want, 1)? {
            Some(reply) => check_res(&reply, &param),
            None => Err(self.timeout_error(id, &param, 1)),
        }
    }

    fn switch_port(&mut self, baud: u32) -> Result<(), BusError> {
        // Host frames still queued would go out at the wrong speed.
        self.wait_until(self.sched.clock().free_at())?;
        self.link.set_baud(baud).map_err(|e| self.lost(e))?;
        self.cfg.baud = baud;
        self.sched.set_baud(baud);
        Ok(())
    }

    /// Best effort after a failed change: the devices already at `new` go
    /// back to `old_level`, and the port to `old`.
    fn switch_back(&mut self, ids: &[u8], old_level: BaudLevel, new: u32, old: u32) {
        if ids.is_empty() || self.switch_port(new).is_err() {
            return;
        }
        for &id in ids {
            if let Err(e) = self.switch_device(id, old_level) {
                tracing::warn!(bus = %self.cfg.name, "device {id} stays at {new} baud: {e}");
            }
        }
        if let Err(e) = self.switch_port(old) {
            tracing::warn!(bus = %self.cfg.name, "port could not return to {old} baud: {e}");
        }
    }
}
