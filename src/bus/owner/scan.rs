//! Discovery by active scan: each id of a range is asked for INFO_01 once,
//! again only if the line carried garbage meanwhile (its reply may have
//! collided with a power-up announcement). A scan is a one-shot request
//! like the others, so setpoints interleave with it and an e-stop ends it.

use std::time::Instant;

use crate::bus::error::BusError;
use crate::bus::wire::Want;
use crate::protocol::command::index;
use crate::protocol::{is_device_id, Config, InfoBlock};

use super::ctx::Ctx;

pub(super) fn scan(ctx: &mut Ctx, first: u8, last: u8) -> Result<Vec<u8>, BusError> {
    if !is_device_id(first) || !is_device_id(last) || first > last {
        return Err(BusError::Invalid(format!(
            "scan range {first}..={last} must lie within 1..=159"
        )));
    }
    let started = Instant::now();
    let mut found = Vec::new();
    for id in first..=last {
        if probe(ctx, id)? {
            found.push(id);
        }
    }
    add_late_answers(ctx, first..=last, started, &mut found);
    Ok(found)
}

/// A reply that came after its deadline (a slow adapter, a loaded host)
/// was taken in while later ids were probed: that device is there too.
fn add_late_answers(
    ctx: &Ctx,
    range: std::ops::RangeInclusive<u8>,
    since: Instant,
    found: &mut Vec<u8>,
) {
    let answered = |id: u8| {
        ctx.sched()
            .registry()
            .get(id)
            .and_then(|e| e.state.info01)
            .is_some_and(|(_, at)| at >= since)
    };
    let late: Vec<u8> = range
        .filter(|id| !found.contains(id) && answered(*id))
        .collect();
    if late.is_empty() {
        return;
    }
    tracing::info!(bus = %ctx.name(), "scan: {late:?} answered after their deadline");
    found.extend(late);
    found.sort_unstable();
}

/// Asks `id` for INFO_01 once; again (up to the configured retries) only
/// if the line carried garbage meanwhile: silence means nobody is there,
/// garbage may be its reply colliding with an announcement.
fn probe(ctx: &mut Ctx, id: u8) -> Result<bool, BusError> {
    let want = Want {
        dev_id: id,
        index: index::INFO_01_R,
    };
    for _ in 0..=ctx.cfg().timing.retries {
        let garbage = ctx.counters().skipped_bytes;
        if ctx
            .try_transact(Config::read(id, InfoBlock::Info01), want, 1)?
            .is_some()
        {
            return Ok(true);
        }
        if ctx.counters().skipped_bytes == garbage {
            return Ok(false);
        }
        ctx.counters().retries += 1;
    }
    Ok(false)
}

/// The scan of the configured range when no ids were given.
pub(super) fn startup(ctx: &mut Ctx) {
    ctx.sched_mut().job_start();
    let (first, last) = (ctx.cfg().scan_first, ctx.cfg().scan_last);
    match scan(ctx, first, last) {
        Ok(found) => {
            tracing::info!(bus = %ctx.name(), ?found, "scan {first}..={last} done");
            ctx.sched_mut().scan_done();
        }
        // Preempted or down: scan again once the bus runs.
        Err(e) => tracing::info!(bus = %ctx.name(), "scan interrupted: {e}"),
    }
}
