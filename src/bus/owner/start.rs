//! `on_start = "disable"`: joints found enabled when the daemon started
//! (their first INFO_01 showed align or run) are disabled before anything
//! else but an e-stop, and read back like any disable. One that does not
//! confirm is tried again, then reported in the log: it stays shown as
//! running, its target unknown.

use crate::bus::error::BusError;
use crate::bus::handle::Targets;
use crate::bus::state::DisabledReason;

use super::ctx::Ctx;
use super::jobs;

/// Disables attempted per joint before the daemon gives up and says so.
const ATTEMPTS: u32 = 3;

pub(super) fn release(ctx: &mut Ctx, ids: Vec<u8>) {
    ctx.sched_mut().job_start();
    for id in ids {
        release_one(ctx, id);
    }
}

fn release_one(ctx: &mut Ctx, id: u8) {
    let mut last = None;
    for _ in 0..ATTEMPTS {
        let targets = Targets::Ids(vec![id]);
        match jobs::disable_because(ctx, targets, DisabledReason::OnStart) {
            Ok(()) => {
                tracing::warn!(bus = %ctx.name(), dev_id = id,
                    "device {id} was found enabled at start: disabled (on_start = \"disable\")");
                return;
            }
            // An e-stop took over: it disables everything itself.
            Err(BusError::Preempted) => return,
            Err(e) => last = Some(e),
        }
    }
    if let Some(e) = last {
        tracing::error!(bus = %ctx.name(), dev_id = id,
            "device {id} was found enabled at start and could not be disabled: {e}");
    }
}
