//! A finger's current limit in a grasp: read (INFO_04), checked against
//! the hold current and the joint's current protection (INFO_05), reduced
//! to the hold current and confirmed by the bus before any finger of the
//! job moves ([`prepare`]); written back and read back however the grasp
//! ends ([`restore`]), even from a finger task unwinding from a panic
//! ([`RestoreOnDrop`]).

use super::plan::{set, Finger, Plan};
use crate::bus::BusHandle;
use crate::control::current_limit;
use crate::protocol::units;
use crate::protocol::{ConfigParam, InfoBlock, ReplyBody};

/// How a finger's limit stands after [`prepare`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prepared {
    /// The limit before, raw (known once INFO_04 was read).
    pub previous: Option<u16>,
    /// A write of the reduced limit was tried: the previous one must go back.
    pub written: bool,
}

/// Reads the limit, checks the hold current fits the joint, writes the
/// hold current as the limit (confirmed by the bus: RES or read-back).
pub(crate) async fn prepare(f: &Finger, plan: &Plan) -> Result<Prepared, (Prepared, String)> {
    let mut p = Prepared {
        previous: None,
        written: false,
    };
    let previous = match current_limit::read(&f.bus, f.id).await {
        Ok(raw) => raw,
        Err(why) => return Err((p, why)),
    };
    p.previous = Some(previous);
    set(&f.slot, |s| {
        s.previous_current_limit_a = Some(units::current_limit_a(previous));
    });
    let limit = match units::current_limit_to_raw(plan.hold_a) {
        Ok(raw) if raw < previous => raw,
        _ => {
            let why = format!(
                "hold_current_a = {} A is not below the joint's own limit ({:.3} A): a grasp holds \
                 with a reduced limit",
                plan.hold_a,
                units::current_limit_a(previous)
            );
            return Err((p, why));
        }
    };
    if let Err(why) = check_protection(f, plan.hold_a).await {
        return Err((p, why));
    }
    p.written = true;
    match f.bus.write_config(f.id, ConfigParam::MaxCur(limit)).await {
        Ok(w) if w.value == limit => Ok(p),
        Ok(w) => Err((
            p,
            format!("the limit read back as raw {} not {limit}", w.value),
        )),
        Err(e) => Err((p, format!("could not reduce the current limit: {e}"))),
    }
}

/// A hold above the joint's protection level would be cut to the
/// protection's cap after its delay: refused, naming both.
async fn check_protection(f: &Finger, hold_a: f64) -> Result<(), String> {
    let reply = f
        .bus
        .read_info(f.id, InfoBlock::Info05)
        .await
        .map_err(|e| format!("could not read the current protection (INFO_05): {e}"))?;
    let ReplyBody::Info05(info) = reply.body() else {
        return Err("the joint answered INFO_05 with another block".into());
    };
    let lv1 = units::current_limit_a(info.protect_cur_lv1);
    if hold_a >= lv1 {
        return Err(format!(
            "hold_current_a = {hold_a} A reaches the joint's current protection level \
             ({lv1:.3} A, PROTECT_CUR_LV1): the protection would cut the hold after its delay"
        ));
    }
    Ok(())
}

/// Writes the previous limit back and reads it back: true only when the
/// read-back shows it. Nothing written before: nothing to restore. Not
/// back: owed ([`current_limit::restore`]), and `settled` says when it is.
pub(crate) async fn restore(
    bus: &BusHandle,
    id: u8,
    p: Prepared,
    settled: impl FnOnce() + Send + 'static,
) -> bool {
    let Some(previous) = p.previous else {
        return !p.written;
    };
    if !p.written {
        return true;
    }
    current_limit::restore(bus, id, previous, "grasp", settled).await
}

/// What says a finger's limit is back once an owed one is.
pub(crate) fn settled_in(
    slot: &crate::control::books::grasps::Slot,
) -> impl FnOnce() + Send + 'static {
    let slot = slot.clone();
    move || set(&slot, |s| s.current_limit_restored = true)
}

/// Writes the previous limit back from a task of its own if the finger's
/// task leaves without having done it (a panic unwinding).
pub(crate) struct RestoreOnDrop {
    pub bus: BusHandle,
    pub id: u8,
    pub prepared: Prepared,
    /// Cleared once the finger restored the limit itself.
    pub armed: bool,
}

impl Drop for RestoreOnDrop {
    fn drop(&mut self) {
        if !self.armed {
            return;
        }
        tracing::error!(
            bus = self.bus.name(),
            id = self.id,
            "grasp ended without restoring the current limit: restoring it"
        );
        let (bus, id, p) = (self.bus.clone(), self.id, self.prepared);
        if let Ok(rt) = tokio::runtime::Handle::try_current() {
            rt.spawn(async move { restore(&bus, id, p, || {}).await });
        }
    }
}
