//! Config writes and the id change: each sent, then confirmed the way its
//! parameter's row says (RES or a read-back, see [`crate::bus::verify`]).
//!
//! A lost confirmation is retried as [`retry_plan`] allows: the read-back
//! alone first, then (only for an idempotent RAM setting) the write again.
//! What ends up confirmed is `Ok`; a read-back that shows another value, or
//! a RES failure, is "not written"; a write that went out and stayed
//! unconfirmed is [`BusError::Unverified`], never a timeout: the device may
//! have taken it. Both are counted (`verify_retries`, `writes_unverified`).

use crate::bus::error::BusError;
use crate::bus::handle::{BusEvent, WriteOutcome};
use crate::bus::verify::{confirmation, retry_plan, Confirm, RetryPlan};
use crate::bus::wire::Want;
use crate::protocol::command::index;
use crate::protocol::params::Field;
use crate::protocol::{is_device_id, Command, Config, ConfigParam, CtrlMode, InfoBlock};

use super::confirm::{check_res, unverified};
use super::ctx::Ctx;
use super::jobs::{known, zero_moved};

/// What one confirmation attempt found.
pub(super) enum Seen {
    /// The value is on the device (RES 1, or the field reads it).
    Confirmed,
    /// The read-back shows this other value: the write did not take.
    Other(u16),
    /// No answer: nothing is known.
    Lost,
}

pub(super) fn set_mode(ctx: &mut Ctx, dev_id: u8, mode: CtrlMode) -> Result<(), BusError> {
    write_config(ctx, dev_id, ConfigParam::CtrlMode(mode)).map(|_| ())
}

pub(super) fn write_config(
    ctx: &mut Ctx,
    dev_id: u8,
    param: ConfigParam,
) -> Result<WriteOutcome, BusError> {
    known(ctx, dev_id)?;
    let how = confirmation(&param).map_err(|why| BusError::Invalid(why.to_string()))?;
    let plan = retry_plan(&param, ctx.cfg().timing.retries);
    let verified_by = match how {
        Confirm::Res => by_res(ctx, dev_id, param, plan)?,
        Confirm::ReadBack { block, field } => {
            by_read_back(ctx, dev_id, param, (block, field), plan)?
        }
        Confirm::Unverifiable => {
            ctx.job_send(&[Command::Config(Config { dev_id, param })])?;
            after_unverifiable(ctx, dev_id, &param);
            "unverifiable"
        }
    };
    let (index, value) = param.index_value();
    Ok(WriteOutcome {
        dev_id,
        index,
        value,
        verified_by,
    })
}

/// Config frames handed to the port so far: tells whether a failed
/// transaction's frame went out.
pub(super) fn config_frames_sent(ctx: &mut Ctx) -> u64 {
    ctx.counters().frames_tx_config
}

/// Each send waits for its RES (a RES cannot be asked for again without
/// sending the write again).
fn by_res(
    ctx: &mut Ctx,
    dev_id: u8,
    param: ConfigParam,
    plan: RetryPlan,
) -> Result<&'static str, BusError> {
    let (idx, _) = param.index_value();
    let want = Want { dev_id, index: idx };
    for send in 0..plan.sends {
        if send > 0 {
            ctx.counters().verify_retries += 1;
        }
        let mark = config_frames_sent(ctx);
        match ctx.try_transact(Config { dev_id, param }, want, 1) {
            Ok(Some(reply)) => return check_res(&reply, &param).map(|()| "res"),
            Ok(None) => {}
            Err(e) if send == 0 && config_frames_sent(ctx) == mark => return Err(e),
            Err(e) => return Err(unverified(ctx.counters(), dev_id, &param, e.to_string())),
        }
    }
    let reason = format!("no RES after {} send(s)", plan.sends);
    Err(unverified(ctx.counters(), dev_id, &param, reason))
}

/// Sends, reads the field back (again if the answer is lost), and sends
/// again while the plan allows and the value is not confirmed.
fn by_read_back(
    ctx: &mut Ctx,
    dev_id: u8,
    param: ConfigParam,
    at: (InfoBlock, Field),
    plan: RetryPlan,
) -> Result<&'static str, BusError> {
    let mut last = Seen::Lost;
    for send in 0..plan.sends {
        if send > 0 {
            ctx.counters().verify_retries += 1;
        }
        if let Err(e) = ctx.job_send(&[Command::Config(Config { dev_id, param })]) {
            // Not sent this time; an earlier send may have taken.
            return Err(match send {
                0 => e,
                _ => unverified(ctx.counters(), dev_id, &param, e.to_string()),
            });
        }
        last = read_after_send(ctx, dev_id, &param, at, plan.reads_per_send)?;
        if matches!(last, Seen::Confirmed) {
            return Ok("read_back");
        }
    }
    if matches!(last, Seen::Other(_)) {
        // "Not written" is said only of a value seen twice: one answer
        // could be a late reply to a read asked before the last send.
        ctx.counters().verify_retries += 1;
        last = read_after_send(ctx, dev_id, &param, at, plan.reads_per_send)?;
    }
    let (index, expected) = param.index_value();
    match last {
        Seen::Confirmed => Ok("read_back"),
        Seen::Other(found) => Err(BusError::VerifyMismatch {
            dev_id,
            index,
            expected,
            found,
        }),
        Seen::Lost => {
            let reason = format!("no read-back answered after {} send(s)", plan.sends);
            Err(unverified(ctx.counters(), dev_id, &param, reason))
        }
    }
}

/// [`read_field`] after the write went out: a failure of the bus (down,
/// preempted) leaves the write unverified.
fn read_after_send(
    ctx: &mut Ctx,
    dev_id: u8,
    param: &ConfigParam,
    at: (InfoBlock, Field),
    reads: u32,
) -> Result<Seen, BusError> {
    read_field(ctx, dev_id, param, at, reads)
        .map_err(|e| unverified(ctx.counters(), dev_id, param, e.to_string()))
}

/// Reads `block` until one read answers (at most `reads` times) and
/// compares the field with the value written.
pub(super) fn read_field(
    ctx: &mut Ctx,
    dev_id: u8,
    param: &ConfigParam,
    (block, field): (InfoBlock, Field),
    reads: u32,
) -> Result<Seen, BusError> {
    let (_, value) = param.index_value();
    let want = Want {
        dev_id,
        index: block.index(),
    };
    for attempt in 0..reads {
        if attempt > 0 {
            ctx.counters().verify_retries += 1;
        }
        if let Some(reply) = ctx.try_transact(Config::read(dev_id, block), want, 1)? {
            let found = field.read(&reply.data);
            return Ok(if found == value {
                Seen::Confirmed
            } else {
                Seen::Other(found)
            });
        }
    }
    Ok(Seen::Lost)
}

fn after_unverifiable(ctx: &mut Ctx, dev_id: u8, param: &ConfigParam) {
    match param {
        ConfigParam::CtrlMode(mode) => {
            ctx.sched_mut().registry_mut().set_mode(dev_id, *mode);
            ctx.setpoints().clear(Some(&[dev_id]));
            ctx.sched_mut().forget_setpoint(dev_id);
        }
        ConfigParam::UpdateFinZero => zero_moved(ctx, dev_id),
        _ => {}
    }
}

pub(super) fn set_id(ctx: &mut Ctx, dev_id: u8, new_id: u8) -> Result<WriteOutcome, BusError> {
    known(ctx, dev_id)?;
    if !is_device_id(new_id) || new_id == dev_id {
        return Err(BusError::Invalid(format!(
            "new id {new_id} must be in 1..=159 and differ from {dev_id}"
        )));
    }
    if ctx.sched().registry().get(new_id).is_some() {
        return Err(BusError::WrongState(format!(
            "id {new_id} is already taken on bus {}",
            ctx.name()
        )));
    }
    let param = ConfigParam::SetId { new_id };
    let cmd = Config { dev_id, param };
    // Sent once: a retry to the old id would reach a device that may have
    // changed with its RES lost (and it is stored to flash).
    let want = Want {
        dev_id: new_id,
        index: index::SET_ID,
    };
    let mark = config_frames_sent(ctx);
    let verified_by = match ctx.try_transact(cmd, want, 1) {
        Ok(Some(reply)) => check_res(&reply, &param).map(|()| "res")?,
        Ok(None) => confirm_new_id(ctx, dev_id, new_id, &param)?,
        Err(e) if config_frames_sent(ctx) == mark => return Err(e),
        Err(e) => return Err(unverified(ctx.counters(), dev_id, &param, e.to_string())),
    };
    rename(ctx, dev_id, new_id);
    Ok(WriteOutcome {
        dev_id: new_id,
        index: index::SET_ID,
        value: param.index_value().1,
        verified_by,
    })
}

/// The RES of an id change did not come: does the new id answer, or
/// still the old one (the change did not take)? Neither: unverified.
fn confirm_new_id(
    ctx: &mut Ctx,
    dev_id: u8,
    new_id: u8,
    param: &ConfigParam,
) -> Result<&'static str, BusError> {
    let attempts = 1 + ctx.cfg().timing.retries;
    let answers = |ctx: &mut Ctx, id: u8| {
        let want = Want {
            dev_id: id,
            index: index::INFO_01_R,
        };
        let read = Config::read(id, InfoBlock::Info01);
        ctx.try_transact(read, want, attempts).map(|r| r.is_some())
    };
    let lost = |ctx: &mut Ctx, reason: String| unverified(ctx.counters(), dev_id, param, reason);
    ctx.counters().verify_retries += 1;
    match answers(ctx, new_id) {
        Ok(true) => return Ok("read_back"),
        Ok(false) => {}
        Err(e) => return Err(lost(ctx, e.to_string())),
    }
    match answers(ctx, dev_id) {
        Ok(true) => Err(BusError::VerifyMismatch {
            dev_id,
            index: index::SET_ID,
            expected: param.index_value().1,
            found: u16::from(dev_id) << 7,
        }),
        Ok(false) => {
            let reason = format!("neither id {new_id} nor id {dev_id} answered; scan the bus");
            Err(lost(ctx, reason))
        }
        Err(e) => Err(lost(ctx, e.to_string())),
    }
}

/// The registry entry and the setpoint slot follow the device. An entry
/// the read-back made for the new id is replaced by the old one's history.
fn rename(ctx: &mut Ctx, old: u8, new: u8) {
    ctx.sched_mut().rename(old, new);
    ctx.setpoints().rename(old, new);
    let bus = ctx.name().to_string();
    ctx.push_event(BusEvent::IdChanged { bus, old, new });
}
