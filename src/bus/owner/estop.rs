//! The emergency stop: disable frames ahead of everything queued, then a
//! read-back of every online device. A device that still drives its motor
//! (it missed every disable, e.g. to noise on its stub) is disabled again
//! and read once more; what could not be confirmed is reported, never
//! assumed.

use std::time::Instant;

use crate::bus::error::BusError;
use crate::bus::handle::{BusEvent, EstopReport};
use crate::bus::registry::drives_motor;
use crate::bus::state::DisabledReason;
use crate::protocol::{Command, Control, ALL_DEVICES};

use super::ctx::Ctx;

/// What reading a device back after the stop found.
enum ReadBack {
    Stopped,
    Driving,
    NoAnswer,
}

/// Disables every device ahead of everything queued (SPEC errata 3:
/// standard control frames, `0xFF` first, then each known device), then
/// confirms it device by device.
pub(super) fn run(ctx: &mut Ctx, generation: u64) {
    let called = ctx
        .shared()
        .estop_called
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take();
    let sent = disable_everything(ctx, DisabledReason::Estop);
    let preempted = ctx.fail_queued(&BusError::Preempted);
    let result = sent.map(|(frames_sent, handed)| {
        let mut report = EstopReport {
            bus: ctx.name().to_string(),
            frames_sent,
            preempted_requests: preempted,
            latency_us: called.map_or(0, |c| {
                handed.saturating_duration_since(c).as_micros() as u64
            }),
            ..EstopReport::default()
        };
        confirm_stopped(ctx, &mut report);
        report
    });
    if let Ok(r) = &result {
        if !r.still_enabled.is_empty() {
            tracing::error!(bus = %ctx.name(), "e-stop: {:?} still enabled after a second disable", r.still_enabled);
        }
    }
    let bus = ctx.name().to_string();
    ctx.push_event(BusEvent::Estop { bus });
    ctx.shared()
        .estop_done
        .send_replace((generation, Some(result)));
    ctx.publish(Instant::now());
}

/// Writes the disable frames and forgets every setpoint; returns the
/// frame count and when they were handed to the port.
pub(super) fn disable_everything(
    ctx: &mut Ctx,
    reason: DisabledReason,
) -> Result<(u32, Instant), BusError> {
    ctx.setpoints()
        .revoke(None, super::jobs::revoked_by(reason));
    ctx.drop_all_setpoints();
    for id in ctx.sched().registry().ids() {
        ctx.sched_mut().registry_mut().note_disabled(id, reason);
    }
    if !ctx.link_is_up() {
        return Err(ctx.down_error());
    }
    // 0xFF, each device, 0xFF again: an e-stop does not wait out a late
    // reply, and one reply can collide with two consecutive host frames
    // (0xFF and device 1's); it cannot reach both ends of the sequence,
    // so every device hears at least one disable.
    let cmds: Vec<Command> = std::iter::once(ALL_DEVICES)
        .chain(ctx.sched().registry().ids())
        .chain(std::iter::once(ALL_DEVICES))
        .map(|id| Command::Control(Control::disable(id)))
        .collect();
    let handed = Instant::now();
    ctx.send(&cmds)?;
    Ok((cmds.len() as u32, handed))
}

/// Reads every known device back; disables again whoever still drives.
/// Offline devices, silent ones and those left when a newer e-stop or a
/// lost port cut the check short are `unconfirmed`.
fn confirm_stopped(ctx: &mut Ctx, report: &mut EstopReport) {
    ctx.sched_mut().job_start();
    let ids = ctx.sched().registry().ids();
    for (n, &id) in ids.iter().enumerate() {
        if !ctx.sched().registry().is_online(id) {
            report.unconfirmed.push(id);
            continue;
        }
        let found = match read_back(ctx, id) {
            Ok(ReadBack::Driving) => {
                report.disabled_again.push(id);
                disable_again(ctx, id)
            }
            other => other,
        };
        match found {
            Ok(ReadBack::Stopped) => report.confirmed.push(id),
            Ok(ReadBack::Driving) => report.still_enabled.push(id),
            Ok(ReadBack::NoAnswer) => report.unconfirmed.push(id),
            Err(e) => {
                tracing::warn!(bus = %ctx.name(), "e-stop read-back cut short: {e}");
                report.unconfirmed.extend_from_slice(&ids[n..]);
                break;
            }
        }
    }
}

fn disable_again(ctx: &mut Ctx, id: u8) -> Result<ReadBack, BusError> {
    ctx.job_send(&[Command::Control(Control::disable(id))])?;
    read_back(ctx, id)
}

/// INFO_01 with the configured retries; silence is an answer here.
fn read_back(ctx: &mut Ctx, id: u8) -> Result<ReadBack, BusError> {
    match super::jobs::read_info01(ctx, id) {
        Ok(info) if drives_motor(info.fsm) => Ok(ReadBack::Driving),
        Ok(_) => Ok(ReadBack::Stopped),
        Err(BusError::Timeout { .. }) => Ok(ReadBack::NoAnswer),
        Err(e) => Err(e),
    }
}
