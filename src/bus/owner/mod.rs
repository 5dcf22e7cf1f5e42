//! The bus owner: one OS thread per bus and the only code that touches its
//! port. It asks the [`Scheduler`](crate::bus::scheduler::Scheduler) for
//! the next slot (e-stop, a queued one-shot request, setpoints within the
//! control budget, a telemetry poll, setpoints again, listen, reopen) and
//! does the I/O the slot names. While a reply is due nothing else is written.
//!
//! A lost port marks the bus down and every device offline; the owner then
//! retries with backoff, failing requests with `Down` meanwhile, and resumes
//! when the port is back. Nothing here can take another bus down.
//!
//! - `ctx`: what the owner's code works with (port, scheduler, publication).
//! - `jobs`, `write`, `write_all`, `estop`, `scan`, `baud`: one-shot requests, functions of a `&mut Ctx`.
//! - `start`: joints found enabled at start, disabled when `on_start = "disable"`.
//! - `probe`: asking a device its firmware revision (`firmware = "auto"`).
//! - `confirm`: reading a RES, naming a config frame in errors.
//! - `stats`: rate windows.

mod baud;
mod confirm;
mod ctx;
mod estop;
mod jobs;
mod lend;
mod probe;
mod scan;
mod start;
mod stats;
mod write;
mod write_all;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::Instant;

use crate::bus::config::{BusConfig, ShutdownState};
use crate::bus::error::BusError;
use crate::bus::handle::{BusShared, Request};
use crate::bus::link::Link;
use crate::bus::scheduler::Slot;
use crate::bus::state::DisabledReason;
use crate::protocol::{ConfigParam, CtrlMode};
use crate::rt::{precise_timers, set_fifo};

use ctx::Ctx;

pub(crate) struct Owner {
    ctx: Ctx,
    stop: Arc<AtomicBool>,
}

impl Owner {
    pub(crate) fn new(
        cfg: BusConfig,
        shared: Arc<BusShared>,
        requests: Receiver<Request>,
        stop: Arc<AtomicBool>,
        link: Link,
    ) -> Self {
        Self {
            ctx: Ctx::new(cfg, shared, requests, link, stop.clone()),
            stop,
        }
    }

    /// The thread's body: runs until [`crate::bus::BusThread::stop`].
    pub(crate) fn run(mut self) {
        precise_timers();
        self.realtime();
        while !self.stop.load(Ordering::Acquire) {
            // A bug must not leave the joints with a dead owner and a stale
            // "up" snapshot: the owner catches it and starts over like after
            // an unplug (its state is rebuilt from the wire).
            let step = catch_unwind(AssertUnwindSafe(|| self.turn()));
            if let Err(panic) = step {
                self.recover_from_panic(panic.as_ref());
            }
        }
        self.shutdown();
    }

    fn recover_from_panic(&mut self, panic: &(dyn std::any::Any + Send)) {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        let ctx = &mut self.ctx;
        tracing::error!(bus = %ctx.name(), "bus owner caught a panic ({what}); reopening the port");
        ctx.counters().owner_panics += 1;
        ctx.sched_mut().job_abort();
        let err = ctx.lost(std::io::Error::other(format!("internal error: {what}")));
        // An e-stop cut short says so now rather than at its caller's timeout.
        let answered = ctx.shared().estop_done.borrow().0;
        let seen = ctx.sched().estop_seen();
        if seen > answered {
            ctx.shared().estop_done.send_replace((seen, Some(Err(err))));
        }
        ctx.publish(Instant::now());
    }

    fn realtime(&mut self) {
        let priority = self.ctx.cfg().timing.rt_priority;
        if priority == 0 {
            return;
        }
        if let Err(e) = set_fifo(0, priority) {
            let note = format!(
                "real-time priority {priority} refused ({e}): replies wait for the CPU under load"
            );
            tracing::info!(bus = %self.ctx.name(), "{note}");
            self.ctx.note_thread(note);
        }
    }

    /// Asks the scheduler for the next slot and does what it names. Errors
    /// have already marked the bus down; the next slot says so.
    fn turn(&mut self) {
        let now = Instant::now();
        let ctx = &mut self.ctx;
        let _ = match ctx.decide(now) {
            Slot::Listen { until } => ctx.wait_until(until),
            Slot::Control(frame) => ctx.send_planned(frame),
            Slot::ControlBatch(frames) => ctx.send_control_batch(frames),
            Slot::Poll { dev_id, block } => ctx.poll(dev_id, block),
            Slot::Batch {
                control,
                dev_id,
                block,
            } => ctx.poll_behind(control, dev_id, block),
            Slot::EStop { generation } => {
                estop::run(ctx, generation);
                Ok(())
            }
            Slot::Request => {
                if let Some(req) = ctx.take_held() {
                    run_request(ctx, req);
                }
                Ok(())
            }
            Slot::Scan => {
                scan::startup(ctx);
                Ok(())
            }
            Slot::Release { ids } => {
                start::release(ctx, ids);
                Ok(())
            }
            Slot::Probe { dev_id } => {
                probe::probe(ctx, dev_id);
                Ok(())
            }
            Slot::Reopen { at } => {
                ctx.while_down(now, at);
                Ok(())
            }
        };
    }

    /// Brings the joints to the configured safe state and closes the port.
    fn shutdown(&mut self) {
        let ctx = &mut self.ctx;
        let disable = ctx.cfg().on_shutdown == ShutdownState::Disable;
        // Said before the frames go, from the last state each joint reported:
        // after a stop, the log is where a user looks for what was released.
        let ids = ctx.sched().registry().ids();
        let driving = driving_ids(ctx);
        if !ctx.ever_up() {
            // A start that never opened the port has nothing to disable.
            tracing::debug!(bus = %ctx.name(), "shutdown: the port was never open");
        } else if disable {
            // The line as an e-stop gets it: behind a USB adapter a poll
            // written blind may still have its reply coming.
            let sent = ctx
                .wait_for_line()
                .and_then(|()| estop::disable_everything(ctx, DisabledReason::Shutdown));
            match sent {
                Ok(_) => {
                    // Let the disable frames leave the wire before the port closes.
                    let _ = ctx.wait_until(ctx.sched().clock().free_at());
                    tracing::info!(bus = %ctx.name(), ?ids, enabled_before = ?driving,
                        "shutdown: disable sent to every joint (on_shutdown = \"disable\")");
                }
                Err(e) => tracing::warn!(bus = %ctx.name(), ?ids, enabled_before = ?driving,
                    "shutdown: could not send the disable: {e}"),
            }
        } else {
            tracing::warn!(bus = %ctx.name(), left_enabled = ?driving,
                "stopping with the joints left enabled (on_shutdown = \"hold\")");
        }
        ctx.fail_queued(&BusError::Stopped);
        ctx.close();
        ctx.publish(Instant::now());
    }
}

/// The joints whose last reported state drives the motor.
fn driving_ids(ctx: &Ctx) -> Vec<u8> {
    let registry = ctx.sched().registry();
    registry
        .ids()
        .into_iter()
        .filter(|id| {
            registry
                .get(*id)
                .and_then(|e| e.state.info01.as_ref())
                .is_some_and(|(info, _)| crate::bus::registry::drives_motor(info.fsm))
        })
        .collect()
}

/// Runs one request and answers its caller (who may have given up: a
/// dropped receiver is nothing to tell).
fn run_request(ctx: &mut Ctx, req: Request) {
    match req {
        Request::Enable { targets, reply } => answer(reply, jobs::enable(ctx, targets), ctx),
        Request::Disable { targets, reply } => answer(reply, jobs::disable(ctx, targets), ctx),
        Request::Jog { dev_id, dir, reply } => answer(reply, jobs::jog(ctx, dev_id, dir), ctx),
        Request::Rezero { dev_id, reply } => answer(reply, jobs::rezero(ctx, dev_id), ctx),
        Request::SetMode {
            dev_id,
            mode,
            reply,
        } => {
            let result = write::set_mode(ctx, dev_id, mode);
            mode_settled(ctx, dev_id, result.is_ok().then_some(mode));
            answer(reply, result, ctx)
        }
        Request::ReadInfo {
            dev_id,
            block,
            reply,
        } => answer(reply, jobs::read_info(ctx, dev_id, block), ctx),
        Request::WriteConfig {
            dev_id,
            param,
            reply,
        } => {
            let result = write::write_config(ctx, dev_id, param);
            if let ConfigParam::CtrlMode(mode) = param {
                mode_settled(ctx, dev_id, result.is_ok().then_some(mode));
            }
            note_written(ctx, result.as_ref().ok());
            answer(reply, result, ctx)
        }
        Request::WriteAll { ids, param, reply } => {
            let result = write_all::write_all(ctx, ids, param);
            if let Ok(all) = &result {
                for (_, outcome) in &all.per_device {
                    note_written(ctx, outcome.as_ref().ok());
                }
            }
            answer(reply, result, ctx)
        }
        Request::WriteFlash { dev_id, reply } => {
            let key = crate::protocol::command::WRITE_FLASH_KEY;
            let param = ConfigParam::WriteFlash { key };
            let result = write::write_config(ctx, dev_id, param);
            note_written(ctx, result.as_ref().ok());
            answer(reply, result, ctx)
        }
        Request::SetId {
            dev_id,
            new_id,
            reply,
        } => answer(reply, write::set_id(ctx, dev_id, new_id), ctx),
        Request::SetBaud { baud, reply } => answer(reply, baud::set_baud(ctx, baud), ctx),
        Request::Scan { first, last, reply } => answer(reply, scan::scan(ctx, first, last), ctx),
        Request::LendPort { job, reply } => answer(reply, lend::lend(ctx, job), ctx),
    }
}

/// A mode write ended: the joint takes commands for `written`, or, when
/// the write failed, for the mode the daemon last knew it in (the epoch
/// advanced either way: nothing from before the change applies).
fn mode_settled(ctx: &mut Ctx, dev_id: u8, written: Option<CtrlMode>) {
    let known = ctx
        .sched()
        .registry()
        .get(dev_id)
        .and_then(|e| e.state.mode);
    let mode = written.or(known);
    ctx.setpoints().authority().mode_set(dev_id, mode);
    if written.is_some() {
        // Entering or leaving speed mode: the speed reference is 0 (the
        // device keeps it in RAM across the change).
        let zero = crate::protocol::Control::set_ref(dev_id, 0, 0);
        if mode == Some(CtrlMode::Speed) {
            let _ = ctx.job_send(&[crate::protocol::Command::Control(zero)]);
        }
    }
}

/// Tells subscribers (and recordings) of a confirmed config write.
fn note_written(ctx: &mut Ctx, outcome: Option<&crate::bus::handle::WriteOutcome>) {
    let Some(o) = outcome else { return };
    let name = crate::protocol::params::by_index(o.index).map_or("unknown", |r| r.name);
    ctx.push_event(crate::bus::events::BusEvent::ConfigWritten {
        bus: ctx.cfg().name.clone(),
        dev_id: o.dev_id,
        index: o.index,
        name,
        value: o.value,
        verified_by: o.verified_by,
    });
}

/// Publishes what the request changed, then answers: a caller that reads
/// the snapshot next finds its own change in it (a mode, a firmware, a target
/// forgotten), not the state of the last periodic publication.
fn answer<T>(
    reply: tokio::sync::oneshot::Sender<Result<T, BusError>>,
    result: Result<T, BusError>,
    ctx: &mut Ctx,
) {
    ctx.publish(Instant::now());
    drop(reply.send(result));
}
