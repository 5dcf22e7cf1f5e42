//! One-shot requests: what each does on the wire and how it is confirmed.
//!
//! - Enable/disable use standard control frames (SPEC errata 3) and are
//!   confirmed by the fsm in a fresh INFO_01.
//! - Config writes and the id change are in `write`; the baud change in `baud`.

use crate::bus::authority::{Epoch, Revoked};
use crate::bus::error::BusError;
use crate::bus::handle::Targets;
use crate::bus::registry::drives_motor;
use crate::bus::state::DisabledReason;
use crate::bus::wire::Want;
use crate::protocol::command::index;
use crate::protocol::status::{active_fault, fault_name, fsm, fsm_name};
use crate::protocol::{
    Command, Config, ConfigParam, Control, CtrlMode, Info01, InfoBlock, Jog, JogDir, Reply,
    ReplyBody, ALL_DEVICES,
};

use super::confirm::unverified;
use super::ctx::Ctx;

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

pub(super) fn known(ctx: &Ctx, id: u8) -> Result<(), BusError> {
    match ctx.sched().registry().get(id) {
        Some(_) => Ok(()),
        // A bus that is down knows no device: the answer is "bus down"
        // (503, as a scan gets), not "unknown device" (404).
        None if !ctx.link_is_up() => Err(ctx.down_error()),
        None => Err(BusError::UnknownDevice {
            bus: ctx.name().to_string(),
            dev_id: id,
        }),
    }
}

/// The ids a control request addresses, each known.
fn resolve(ctx: &Ctx, targets: &Targets) -> Result<Vec<u8>, BusError> {
    match targets {
        Targets::All => Ok(ctx.sched().registry().online_ids()),
        Targets::Ids(ids) => {
            ids.iter().try_for_each(|id| known(ctx, *id))?;
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

pub(super) fn enable(ctx: &mut Ctx, targets: Targets) -> Result<(), BusError> {
    let ids = resolve(ctx, &targets)?;
    // An enable holds the joint where it stands (SPEC §4.1: EN = 1 powers
    // up and holds; references apply only with EN = 3): no target written
    // before it (before a disable, a power cut, a fault, an e-stop) may
    // follow it. Cleared before the frame, so a target written from here
    // on is a new one and goes out (after align, too).
    let reached = addressed(ctx, &targets, &ids);
    forget_targets(ctx, &reached);
    // Nothing admitted before this enable applies after it; the joint takes
    // commands again only once the enable is confirmed under this epoch (an
    // e-stop or disable meanwhile advances it, and the joint stays refused).
    let epochs: Vec<(u8, Epoch)> = reached
        .iter()
        .map(|&id| {
            (
                id,
                ctx.setpoints().authority().revoke(id, Revoked::Reenabled),
            )
        })
        .collect();
    hold_before_enable(ctx, &reached)?;
    ctx.job_send(&control_frames(&targets, &ids, Control::enable))?;
    for &id in &reached {
        ctx.sched_mut().registry_mut().note_enabled(id);
    }
    for &id in &ids {
        // Rev 2.0.8 passes through `start` on the way to run.
        if let Err(e) = await_fsm(ctx, id, "enable", drives_motor) {
            enable_after_transit(ctx, id).ok_or(e)??;
        }
        if let Some((_, epoch)) = epochs.iter().find(|(e_id, _)| *e_id == id) {
            ctx.setpoints().authority().arm(id, *epoch);
        }
    }
    Ok(())
}

/// What an enable holds: a joint in speed mode keeps the speed reference it
/// was last sent across a disable (the device holds it in RAM), so a zero
/// goes to it before its enable and an enable in speed mode never spins
/// (with its position slot where it was measured: a device that reset
/// unseen runs position mode, and reads that slot as its target); a
/// joint that already drives its motor ignores the enable frame and would
/// go on towards a target admitted before it, so it is told to hold where
/// it was last measured.
fn hold_before_enable(ctx: &mut Ctx, ids: &[u8]) -> Result<(), BusError> {
    let reg = ctx.sched().registry();
    let holds: Vec<Command> = ids
        .iter()
        .filter_map(|&id| {
            let entry = reg.get(id)?;
            let here = reg.slot_info(id).and_then(|s| s.measured);
            if entry.state.mode == Some(CtrlMode::Speed) {
                return Some(Control::set_ref(id, here.unwrap_or(0), 0));
            }
            let driving = entry
                .state
                .info01
                .is_some_and(|(info, _)| drives_motor(info.fsm));
            let here = here?;
            driving.then(|| Control::set_ref(id, here, hold_speed_limit()))
        })
        .map(Command::Control)
        .collect();
    if holds.is_empty() {
        return Ok(());
    }
    ctx.job_send(&holds)
}

/// The speed limit of a hold: slow (3000 rpm rotor, ~32 °/s at the output),
/// in the newer speed base, so older firmware reads it slower still.
fn hold_speed_limit() -> i16 {
    crate::protocol::units::speed_limit_to_raw(
        3000.0,
        crate::protocol::units::FirmwareVersion::SPEED_BASE_50K,
    )
    .unwrap_or(0)
}

/// Reads of a device in a passing state (rev 2.0.8's stop, brake, init,
/// precharge) before the daemon gives up waiting for it to settle.
const SETTLE_CHECKS: u32 = 50;

/// Rev 2.0.8 ignores an enable while it stops, brakes or starts up (the
/// simulator's reading; the vendor's document is silent): an enable right
/// after a disable can be lost that way. `None` when the device is not in
/// such a state (the enable failed for another reason); otherwise the
/// device is awaited until it settles and enabled once more.
fn enable_after_transit(ctx: &mut Ctx, id: u8) -> Option<Result<(), BusError>> {
    match read_info01(ctx, id) {
        Ok(info) if passing(info.fsm) || info.fsm == fsm::READY => {}
        _ => return None,
    }
    Some(settle_and_enable(ctx, id))
}

fn passing(state: u8) -> bool {
    matches!(state, fsm::STOP | fsm::BRAKE | fsm::INIT | fsm::PRECHARGE)
}

fn settle_and_enable(ctx: &mut Ctx, id: u8) -> Result<(), BusError> {
    let mut settled = false;
    for _ in 0..SETTLE_CHECKS {
        if !passing(read_info01(ctx, id)?.fsm) {
            settled = true;
            break;
        }
    }
    if !settled {
        return Err(BusError::WrongState(format!(
            "device {id} did not settle after stopping; enable it again"
        )));
    }
    tracing::info!(bus = %ctx.name(), dev_id = id,
        "enable: device {id} ignored the enable while stopping; enabled again");
    ctx.job_send(&[Command::Control(Control::enable(id))])?;
    await_fsm(ctx, id, "enable", drives_motor).map(drop)
}

pub(super) fn disable(ctx: &mut Ctx, targets: Targets) -> Result<(), BusError> {
    disable_because(ctx, targets, DisabledReason::Request)
}

/// A disable, recorded with why (a request, the start policy).
pub(super) fn disable_because(
    ctx: &mut Ctx,
    targets: Targets,
    reason: DisabledReason,
) -> Result<(), BusError> {
    let ids = resolve(ctx, &targets)?;
    let reached = addressed(ctx, &targets, &ids);
    let why = revoked_by(reason);
    for &id in &reached {
        ctx.setpoints().authority().revoke(id, why);
    }
    ctx.job_send(&control_frames(&targets, &ids, Control::disable))?;
    forget_targets(ctx, &reached);
    for &id in &reached {
        // Before the read-back: ready from now on is no reset.
        ctx.sched_mut().registry_mut().note_disabled(id, reason);
    }
    for &id in &ids {
        // Released is what counts: rev 2.0.8 passes through `stop` (and
        // `brake` while still turning) on the way to ready.
        await_fsm(ctx, id, "disable", |f| !drives_motor(f))?;
    }
    Ok(())
}

/// What a disable for `reason` ends a joint's moves and streams with.
pub(super) fn revoked_by(reason: DisabledReason) -> Revoked {
    match reason {
        DisabledReason::Estop => Revoked::Estopped,
        DisabledReason::Reset => Revoked::Reset,
        DisabledReason::Fault => Revoked::Fault,
        DisabledReason::Request | DisabledReason::OnStart | DisabledReason::Shutdown => {
            Revoked::Disabled
        }
    }
}

/// Every device a control frame reached: `0xFF` reaches offline devices too.
fn addressed(ctx: &Ctx, targets: &Targets, ids: &[u8]) -> Vec<u8> {
    match targets {
        Targets::All => ctx.sched().registry().ids(),
        Targets::Ids(_) => ids.to_vec(),
    }
}

/// The joints hold no target of ours: stored, pending and sent ones go.
fn forget_targets(ctx: &mut Ctx, ids: &[u8]) {
    ctx.setpoints().clear(Some(ids));
    for &id in ids {
        ctx.sched_mut().forget_setpoint(id);
        ctx.sched_mut().registry_mut().forget_target(id);
    }
}

/// Reads INFO_01 until the fsm satisfies `ok`; a fault is reported by name.
fn await_fsm(ctx: &mut Ctx, id: u8, what: &str, ok: fn(u8) -> bool) -> Result<Info01, BusError> {
    let mut last = None;
    for _ in 0..FSM_CHECKS {
        let info = read_info01(ctx, id)?;
        if ok(info.fsm) {
            return Ok(info);
        }
        if info.fsm == fsm::FAULT {
            return Err(BusError::WrongState(format!(
                "device {id} is in fault: {}",
                fault_name(active_fault(info.err_code))
            )));
        }
        last = Some(info.fsm);
    }
    Err(BusError::WrongState(format!(
        "device {id} did not {what}: its state is {}",
        last.map_or("unknown", fsm_name)
    )))
}

pub(super) fn read_info01(ctx: &mut Ctx, id: u8) -> Result<Info01, BusError> {
    match read_info(ctx, id, InfoBlock::Info01)?.body() {
        ReplyBody::Info01(info) => Ok(info),
        _ => Err(BusError::UnexpectedReply(
            "INFO_01 read returned another block".into(),
        )),
    }
}

pub(super) fn jog(ctx: &mut Ctx, dev_id: u8, dir: JogDir) -> Result<(), BusError> {
    known(ctx, dev_id)?;
    let info = read_info01(ctx, dev_id)?;
    if info.fsm != fsm::RUN {
        return Err(BusError::WrongState(format!(
            "jog needs an enabled joint; device {dev_id} is {}",
            fsm_name(info.fsm)
        )));
    }
    ctx.job_send(&[Command::Jog(Jog { dev_id, dir })])?;
    zero_moved(ctx, dev_id);
    Ok(())
}

pub(super) fn rezero(ctx: &mut Ctx, dev_id: u8) -> Result<(), BusError> {
    known(ctx, dev_id)?;
    let cmd = Config {
        dev_id,
        param: ConfigParam::UpdateFinZero,
    };
    ctx.job_send(&[Command::Config(cmd)])?;
    // Handed to the port now, on the wire a little later: measuring from
    // here bounds the joint's travel since from above.
    let sent = std::time::Instant::now();
    zero_moved(ctx, dev_id);
    // The zero moved or not: a read that fails says nothing about which.
    let angle = match read_info01(ctx, dev_id) {
        Ok(info) => info.angle,
        Err(e) => {
            let param = ConfigParam::UpdateFinZero;
            return Err(unverified(ctx.counters(), dev_id, &param, e.to_string()));
        }
    };
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
pub(super) fn zero_moved(ctx: &mut Ctx, id: u8) {
    // A move or stream admitted in the old frame would carry on in the new
    // one, shifted: it ends (the joint stays enabled).
    ctx.setpoints().authority().advance(id, Revoked::ZeroMoved);
    ctx.sched_mut().registry_mut().zero_moved(id);
    ctx.setpoints().clear(Some(&[id]));
    ctx.sched_mut().forget_setpoint(id);
}

pub(super) fn read_info(ctx: &mut Ctx, dev_id: u8, block: InfoBlock) -> Result<Reply, BusError> {
    known(ctx, dev_id)?;
    let want = Want {
        dev_id,
        index: block.index(),
    };
    ctx.transact(Config::read(dev_id, block), want)
}
