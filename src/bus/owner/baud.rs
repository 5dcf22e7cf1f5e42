//! A bus-wide baud change (SPEC §4.3 index 15): every online device is
//! switched first (each answers RES at the old baud, then listens only at
//! the new one), then the port; each device is then read back at the new
//! baud. If a device refuses, the ones already switched are switched back.
//! A device whose RES is lost may have switched: that is reported
//! unverified (and it is switched back with the others), never "not changed".

use crate::bus::error::BusError;
use crate::bus::handle::BusEvent;
use crate::bus::wire::Want;
use crate::protocol::command::index;
use crate::protocol::{BaudLevel, Config, ConfigParam, Info04, InfoBlock};

use super::confirm::check_res;
use super::confirm::unverified;
use super::ctx::Ctx;
use super::write::config_frames_sent;

pub(super) fn set_baud(ctx: &mut Ctx, baud: u32) -> Result<(), BusError> {
    let level = BaudLevel::from_baud(baud).ok_or_else(|| {
        BusError::Invalid(format!(
            "baud {baud} is not one of 500000, 230400, 115200, 38400, 19200"
        ))
    })?;
    let old = ctx.baud();
    if baud == old {
        return Ok(());
    }
    let old_level = BaudLevel::from_baud(old)
        .ok_or_else(|| BusError::Invalid(format!("the port runs at {old}, not a SPEC baud")))?;
    let ids = ctx.sched().registry().online_ids();
    if ids.is_empty() {
        return Err(BusError::WrongState(format!(
            "no device is online on bus {} to change its baud",
            ctx.name()
        )));
    }
    // Until every device and the port agree, an e-stop would not reach
    // all of them: this phase (a few ms) runs to its end, then the e-stop.
    ctx.sched_mut().set_exclusive(true);
    let switched = switch_all(ctx, &ids, level, old_level, baud, old);
    ctx.sched_mut().set_exclusive(false);
    switched?;
    confirm_level(ctx, &ids, level)?;
    let bus = ctx.name().to_string();
    ctx.push_event(BusEvent::BaudChanged { bus, baud });
    Ok(())
}

/// Each device, then the port; on a refusal the switched ones go back.
fn switch_all(
    ctx: &mut Ctx,
    ids: &[u8],
    level: BaudLevel,
    old_level: BaudLevel,
    baud: u32,
    old: u32,
) -> Result<(), BusError> {
    let mut touched = Vec::new();
    for &id in ids {
        let result = switch_device(ctx, id, level);
        // A device whose RES was lost may have switched.
        if result.is_ok() || matches!(result, Err(BusError::Unverified { .. })) {
            touched.push(id);
        }
        if let Err(e) = result {
            switch_back(ctx, &touched, old_level, baud, old);
            return Err(e);
        }
    }
    ctx.switch_port(baud)
}

/// Every device answers at the new baud and reports the new level. Each
/// has confirmed by RES already: a read that does not answer leaves the
/// change unverified, not undone.
fn confirm_level(ctx: &mut Ctx, ids: &[u8], level: BaudLevel) -> Result<(), BusError> {
    for &id in ids {
        let read = super::jobs::read_info(ctx, id, InfoBlock::Info04).map_err(|e| {
            let param = ConfigParam::BaudRate(level);
            let reason = format!("RES came at the old baud; the read at the new one failed: {e}");
            unverified(ctx.counters(), id, &param, reason)
        })?;
        let info = Info04::from_bytes(&read.data);
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
/// unheard if the first attempt switched it). A lost RES is unverified.
fn switch_device(ctx: &mut Ctx, id: u8, level: BaudLevel) -> Result<(), BusError> {
    let param = ConfigParam::BaudRate(level);
    let want = Want {
        dev_id: id,
        index: index::BAUD_RATE,
    };
    let mark = config_frames_sent(ctx);
    match ctx.try_transact(Config { dev_id: id, param }, want, 1) {
        Ok(Some(reply)) => check_res(&reply, &param),
        Ok(None) => Err(unverified(ctx.counters(), id, &param, "no RES".into())),
        Err(e) if config_frames_sent(ctx) == mark => Err(e),
        Err(e) => Err(unverified(ctx.counters(), id, &param, e.to_string())),
    }
}

/// Best effort after a failed change: the devices already at `new` go
/// back to `old_level`, and the port to `old`.
fn switch_back(ctx: &mut Ctx, ids: &[u8], old_level: BaudLevel, new: u32, old: u32) {
    if ids.is_empty() || ctx.switch_port(new).is_err() {
        return;
    }
    for &id in ids {
        if let Err(e) = switch_device(ctx, id, old_level) {
            tracing::warn!(bus = %ctx.name(), "device {id} stays at {new} baud: {e}");
        }
    }
    if let Err(e) = ctx.switch_port(old) {
        tracing::warn!(bus = %ctx.name(), "port could not return to {old} baud: {e}");
    }
}
