//! The simulator's one OS thread: reads host bytes with precise timeouts,
//! timestamps them, runs the engine, and writes each reply at the instant
//! the model says its last byte arrives: it sleeps (`ppoll`, timer slack
//! 1 ns) to just before that instant, by as much as its own sleeps have
//! ended late lately ([`WakeLateness`]), then spins the rest of the way.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::rt::wake::WakeLateness;

use super::engine::{Delivery, Engine};
use super::line::Line;

/// Longest wait without an event, so requests and shutdown are seen promptly.
const MAX_IDLE: Duration = Duration::from_millis(2);
/// Host frames the simulated transmit path (driver buffer, adapter FIFO)
/// holds before the host's writes stall: 20 KiB, 0.4 s at 500000 baud.
/// Larger than a bare UART driver's 4 KiB so that a simulator thread starved
/// by a busy machine for tens of ms does not open gaps in a saturated line.
const MAX_BACKLOG: usize = 1024;
const READ_BUF: usize = 4096;
/// How long `inject(Unplug|Replug)` waits for the thread to act.
const LINE_OP_TIMEOUT: Duration = Duration::from_secs(2);

/// Unplug and replug act on the line, which only the runner owns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LineOp {
    Unplug,
    Replug,
}

#[derive(Debug, Default)]
struct Ops {
    pending: Vec<(u64, LineOp)>,
    next_seq: u64,
    done_seq: u64,
}

/// What handles share with the runner besides the engine.
#[derive(Debug, Default)]
pub(crate) struct Control {
    shutdown: AtomicBool,
    ops: Mutex<Ops>,
    done: Condvar,
}

impl Control {
    fn lock(&self) -> MutexGuard<'_, Ops> {
        self.ops.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn request_shutdown(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
    }

    fn stopping(&self) -> bool {
        self.shutdown.load(Ordering::SeqCst)
    }

    /// Queues a line operation and waits (bounded) until the runner did it.
    pub(crate) fn line_op(&self, op: LineOp) {
        let mut ops = self.lock();
        ops.next_seq += 1;
        let seq = ops.next_seq;
        ops.pending.push((seq, op));
        let deadline = Instant::now() + LINE_OP_TIMEOUT;
        while ops.done_seq < seq && !self.stopping() {
            let now = Instant::now();
            if now >= deadline {
                tracing::warn!("simulator thread did not act on {op:?} in time");
                return;
            }
            ops = self
                .done
                .wait_timeout(ops, deadline - now)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }
}

pub(crate) fn lock_engine(engine: &Mutex<Engine>) -> MutexGuard<'_, Engine> {
    engine.lock().unwrap_or_else(|p| p.into_inner())
}

/// A low real-time priority: above every normal thread, below the kernel's own.
const REALTIME_PRIORITY: u8 = 10;

/// Moves this thread to SCHED_FIFO; a refusal (no privilege) is only logged.
fn set_realtime() {
    if let Err(e) = crate::rt::set_fifo(0, REALTIME_PRIORITY) {
        tracing::info!(
            "simulator: real-time priority refused ({e}): its devices answer late when the host is busy"
        );
    }
}

struct Runner {
    engine: Arc<Mutex<Engine>>,
    line: Box<dyn Line>,
    ctl: Arc<Control>,
    buf: Vec<u8>,
    /// How late this thread wakes: it stops sleeping that much before a
    /// delivery is due and spins the rest. Learnt, not fixed: a host whose
    /// idle CPU takes 200 µs to wake needs a long lead, and on a quiet one a
    /// long lead is CPU spent spinning.
    wake: WakeLateness,
}

/// The thread body: runs until shutdown is requested.
pub(crate) fn run(
    engine: Arc<Mutex<Engine>>,
    line: Box<dyn Line>,
    ctl: Arc<Control>,
    realtime: bool,
) {
    crate::rt::precise_timers();
    if realtime {
        set_realtime();
    }
    let mut r = Runner {
        engine,
        line,
        ctl,
        buf: vec![0; READ_BUF],
        wake: WakeLateness::default(),
    };
    while !r.ctl.stopping() {
        r.do_line_ops();
        r.turn();
    }
}

impl Runner {
    /// One turn: wait for input or the next event, then run what is due.
    fn turn(&mut self) {
        let (next, delivery, backlog) = {
            let mut e = lock_engine(&self.engine);
            e.tick(Instant::now());
            (e.next_event(), e.next_delivery(), e.host_backlog())
        };
        let can_read = !self.line.is_unplugged() && backlog < MAX_BACKLOG;
        let now = Instant::now();
        // An adapter model holds bytes for the host: their release is a
        // delivery like the engine's.
        let release = self.line.next_release();
        let Some(due) = [next, release].into_iter().flatten().min() else {
            self.wait(now + MAX_IDLE, can_read);
            return;
        };
        // Only bytes due at the host need the spin; the engine's own events
        // carry their modelled instants, so running them a little late is harmless.
        let spin_from = match (delivery, release) {
            (Some(d), _) | (_, Some(d)) if d == due => self.wake.wake_at(due),
            _ => due,
        };
        if now < spin_from {
            let until = spin_from.min(now + MAX_IDLE);
            if self.wait(until, can_read) {
                self.wake.observe(until, Instant::now());
            }
            return;
        }
        while Instant::now() < due {
            if can_read {
                self.read(Duration::ZERO);
            }
            std::hint::spin_loop();
        }
        self.run_due();
    }

    /// Sleeps until `until`, returning early if host bytes arrive; true
    /// when it slept the whole way (how late it woke is then worth knowing).
    fn wait(&mut self, until: Instant, can_read: bool) -> bool {
        let left = until.saturating_duration_since(Instant::now());
        if can_read {
            self.read(left) == Some(0)
        } else {
            std::thread::sleep(left);
            true
        }
    }

    /// Reads host bytes for up to `timeout`; returns how many came (`None`
    /// when the line failed and the thread slept instead).
    fn read(&mut self, timeout: Duration) -> Option<usize> {
        match self.line.read_timeout(&mut self.buf, timeout) {
            Ok(0) => Some(0),
            Ok(n) => {
                let at = self.line.take_read_at().unwrap_or_else(Instant::now);
                let baud = self.line.host_baud();
                let undated = self.line.take_undated_reads();
                let slipped = self.line.take_slipped_writes();
                let mut engine = lock_engine(&self.engine);
                engine.host.read(undated, slipped);
                engine.on_host_bytes(&self.buf[..n], at, baud);
                Some(n)
            }
            Err(e) => {
                tracing::debug!("simulator read: {e}");
                std::thread::sleep(MAX_IDLE);
                None
            }
        }
    }

    fn run_due(&mut self) {
        if let Err(e) = self.line.flush_due(Instant::now()) {
            tracing::debug!("simulator adapter release: {e}");
        }
        let baud = self.line.host_baud();
        let mut engine = lock_engine(&self.engine);
        let out: Vec<Delivery> = engine.advance(Instant::now(), baud);
        for d in out {
            let taken = self.line.write(&d.bytes).unwrap_or(0);
            engine.host.delivered(d.due, Instant::now());
            if taken < d.bytes.len() {
                engine.host.overrun(d.bytes.len() - taken);
            }
        }
    }

    fn do_line_ops(&mut self) {
        let pending = std::mem::take(&mut self.ctl.lock().pending);
        let Some(&(last, _)) = pending.last() else {
            return;
        };
        for (_, op) in pending {
            let unplug = op == LineOp::Unplug;
            let result = if unplug {
                self.line.unplug()
            } else {
                self.line.replug()
            };
            if let Err(e) = result {
                tracing::warn!("simulator {op:?} failed: {e}");
            }
            lock_engine(&self.engine).set_unplugged(self.line.is_unplugged());
        }
        self.ctl.lock().done_seq = last;
        self.ctl.done.notify_all();
    }
}
