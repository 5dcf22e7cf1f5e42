//! The port lent to a one-shot job ([`crate::bus::loan`]): refused while a
//! joint drives its motor (a check of the line must not leave an enabled
//! joint unwatched); lent with the wire free and every poll answered; taken
//! back at the bus's baud with its input dropped, the line model listening
//! again before the next frame. An e-stop asked meanwhile, or the bus
//! stopping, stops the job at its next frame; the e-stop or the shutdown
//! runs as soon as the port is back.

use std::sync::atomic::Ordering;
use std::time::Instant;

use crate::bus::error::BusError;
use crate::bus::loan::{PortJob, PortLoan};
use crate::transport::adapter::{AdapterInfo, AdapterModel};

use super::ctx::Ctx;

pub(super) fn lend(ctx: &mut Ctx, job: PortJob) -> Result<(), BusError> {
    if !ctx.link_is_up() {
        return Err(ctx.down_error());
    }
    let driving = super::driving_ids(ctx);
    if !driving.is_empty() {
        return Err(BusError::WrongState(format!(
            "joints {driving:?} on bus {} are enabled: disable them before the port is checked",
            ctx.name()
        )));
    }
    ctx.wait_until(ctx.sched().clock().free_at())?;
    let loan = loan_of(ctx);
    tracing::info!(bus = %ctx.name(), "port lent to a check; polling paused");
    let started = Instant::now();
    ctx.with_port(|port| job.run(port, &loan));
    let baud = ctx.baud();
    ctx.switch_port(baud)?;
    ctx.relisten(Instant::now());
    tracing::info!(bus = %ctx.name(), took_ms = started.elapsed().as_millis() as u64,
        "port taken back; polling resumes");
    Ok(())
}

fn loan_of(ctx: &Ctx) -> PortLoan {
    let shared = ctx.shared().clone();
    let stopping = ctx.stopping();
    let at_loan = ctx.estop_generation();
    PortLoan {
        bus: ctx.name().to_string(),
        path: ctx.path().to_path_buf(),
        baud: ctx.baud(),
        adapter: ctx
            .adapter_info()
            .cloned()
            .unwrap_or_else(|| configured(ctx.sched().clock().adapter())),
        notes: ctx.port_notes().to_vec(),
        ids: ctx.sched().registry().ids(),
        reply_margin: std::time::Duration::from_micros(ctx.reply_margin_us()),
        stop_asked: Box::new(move || {
            stopping.load(Ordering::Acquire)
                || shared.estop_generation.load(Ordering::SeqCst) > at_loan
        }),
    }
}

/// A handed-in transport reports no adapter: the one the config names.
fn configured(model: AdapterModel) -> AdapterInfo {
    AdapterInfo {
        model,
        found_by: "set in the config (the port reports none)".into(),
        tty_without_usb: false,
        usb: false,
    }
}
