//! The wire-accurate simulator of a bus of joint modules: the daemon's
//! embedded default, every integration test's fixture, the load of every
//! benchmark. Its behaviour comes from SPEC.md; its bytes from
//! [`crate::protocol`].
//!
//! # Layout
//! - [`config`]: [`SimConfig`], [`parse_ids`], [`SimError`].
//! - [`wire`]: the half-duplex line and its referee (queueing, collisions), pure.
//! - [`busy`]: line occupancy accounting.
//! - [`engine`]: the whole bus as a function of timestamps (wire + devices + faults).
//! - [`device`]: one module's state machine and SPEC behaviour, pure.
//! - [`firmware`]: the firmware profiles (V2.0.1, rev 2.0.8): the one place
//!   that says what each revision does differently, and the assumptions made
//!   where the SPEC is silent.
//! - [`physics`]: angle, speed, current, protection, burst, temperature.
//! - [`object`]: a compliant object a finger closes on (what a grasp holds).
//! - [`params`]: RAM/flash parameters (storage, defaults and INFO layout from
//!   [`crate::protocol::params`]) and the JSON state file.
//! - [`faults`]: run-time fault injection ([`Fault`]).
//! - [`line`], [`pty`]: the device end of an in-memory pipe or a pseudo-terminal.
//! - [`runner`]: the dedicated thread that moves bytes at their modelled instants.
//! - [`host_side`]: what the runner saw of the host's side: delivery errors,
//!   writes it could not date or that slipped a frame, bytes not taken.
//! - [`stats`], [`log`], [`view`]: what observers see.
//! - [`measure`]: real delivery times against the model (`jointd sim --measure N`).
//! - [`cli`], [`console`]: `jointd sim` and its stdin fault commands.
//!
//! # The wire model
//! Every frame occupies 200/baud s of one half-duplex line. A host frame's
//! interval starts when its bytes arrive (or when the previous host frame
//! leaves the line: *queued ahead*, as a UART FIFO). A device acts on a frame
//! when its last byte arrives; a reply starts a turnaround later and reaches
//! the host when its last byte would. Any two transmissions that overlap
//! collide: the host gets garbage, the device applies nothing. Busy time is
//! the union of frames on the line plus the turnaround before each reply.
//!
//! # Modelling choices SPEC leaves open
//! - A baud change (index 15) is RAM: it takes effect after the RES and is
//!   kept over a reboot only after WRITE_FLASH. SET_ID is flash at once.
//! - Power-up announcements are staggered one frame slot per device (by bus
//!   position) so a healthy bus can be discovered from them.
//! - Enable holds the current angle; references sent while disabled are kept
//!   but replaced by that hold on enable. Jog and references in READY do nothing.
//! - COMM_SILENT with a non-zero value silences the device; with 0 it speaks
//!   again; a reboot or power cycle also ends the silence.
//! - UPDATE_ENC_ZERO in READY makes the next enable align again; while
//!   enabled it does nothing. Rev 2.0.8 firmware answers RES (success /
//!   failure), V2.0.1 nothing.
//! - Each device runs the firmware of one protocol revision (V2.0.1 unless
//!   [`SimConfig::firmware`] says otherwise): what rev 2.0.8 changes, and the
//!   choices made where the SPEC is silent, are listed in [`firmware`].
//! - The output zero set by a jog or UPDATE_FIN_ZERO survives a power cycle.
//! - Under-voltage reports err 5 (as the captured vendor frame does); it faults
//!   an enabled device. A stall latches err 8 after `stall_fault_after` of
//!   pushing; disable clears a fault whose cause is gone.
//! - The current cap (MAX_CUR, or PROTECT_CUR_LIMIT while protection holds)
//!   limits the reported current, not the motion of a free joint.
//! - A hard stop ([`SimConfig::hard_stops`], `--hard-stop ID=DEG`) is a
//!   mechanical end of travel: the joint cannot pass it, and pushing into
//!   it is a stall (current up to the cap, err 8 after `stall_fault_after`).
//! - An object ([`SimConfig::objects`], `--object ID=DEG:NM_PER_DEG`, or
//!   [`Fault::Object`] at run time) is elastic: pressing into it takes q
//!   current in proportion to the depth ([`object::OUTPUT_NM_PER_A`]), the
//!   joint presses only as deep as its current cap pays for, and resting
//!   against it in balance is no stall. [`Fault::RemoveObject`] pulls it away.
//!
//! ```no_run
//! use jointd::sim::{parse_ids, SimConfig, Simulator};
//! let sim = Simulator::spawn_pty(SimConfig::new(parse_ids("1-16")?, 500_000))?;
//! if let Some(path) = sim.device_path() {
//!     println!("{}", path.display());
//! }
//! # Ok::<(), jointd::sim::SimError>(())
//! ```

pub(crate) mod adapter;
pub(crate) mod busy;
pub mod cli;
pub(crate) mod config;
pub(crate) mod console;
pub(crate) mod device;
pub(crate) mod engine;
mod error;
pub(crate) mod faults;
pub mod firmware;
pub(crate) mod host_side;
pub(crate) mod line;
pub(crate) mod log;
pub(crate) mod measure;
mod motor;
pub mod object;
pub(crate) mod params;
pub(crate) mod physics;
pub(crate) mod pty;
pub(crate) mod rng;
pub(crate) mod runner;
pub(crate) mod stats;
pub(crate) mod usb_clock;
pub(crate) mod view;
pub(crate) mod wire;
pub(crate) mod write_delay;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

pub use crate::transport::adapter::AdapterModel;
pub use config::{parse_ids, SimConfig, SimError, SimObject};
pub use faults::Fault;
pub use firmware::Firmware;
pub use log::{collision_context, WireFrame};
pub use params::Params;
pub use stats::{FrameKinds, SimStats};
pub use view::DeviceView;
pub use write_delay::WriteDelay;

use crate::transport::memory::{self, MemoryPort};
use crate::transport::taken::TakenCount;
use crate::transport::tty::{PortSetup, TtyPort};
use crate::transport::{Opener, Transport};
use engine::Engine;
use line::{Line, MemoryLine};
use pty::PtyLine;
use runner::{lock_engine, Control, LineOp};

/// What a bus reaching the simulator over the in-memory pipe shows as its
/// path (there is no tty to name).
pub const MEMORY_LINE_PATH: &str = "memory";

/// Starts simulated buses.
#[derive(Debug)]
pub struct Simulator;

impl Simulator {
    /// A bus behind a pseudo-terminal; `device_path()` is the tty to open.
    pub fn spawn_pty(cfg: SimConfig) -> Result<SimHandle, SimError> {
        cfg.validate()?;
        let line = PtyLine::open(cfg.baud).map_err(SimError::Pty)?;
        let path = line.path().map(PathBuf::from);
        SimHandle::spawn(&cfg, Box::new(line), path)
    }

    /// A bus behind an in-memory pipe; returns the host end.
    pub fn spawn_memory(cfg: SimConfig) -> Result<(SimHandle, MemoryPort), SimError> {
        cfg.validate()?;
        let (host, device) = memory::pair(cfg.baud);
        let handle = SimHandle::spawn(&cfg, Box::new(MemoryLine::new(device)), None)?;
        Ok((handle, host))
    }

    /// A bus over the line its adapter model needs: a pty (opened by path,
    /// like hardware; the host end is `None`) on a native line, the
    /// in-memory pipe (its host end returned) behind a USB model. Behind a
    /// USB adapter the bus owner writes polls without waiting for their
    /// replies, each timed to reach the wire within a USB frame of its
    /// write, as an adapter takes it; a pty's kernel worker may pass a write
    /// on a millisecond or more late, which no adapter does, and the referee
    /// then counts collisions the daemon did not make. The pipe tells the
    /// model when each write was made.
    pub fn spawn_for(cfg: SimConfig) -> Result<(SimHandle, Option<MemoryPort>), SimError> {
        if cfg.adapter.is_latent() {
            let (sim, host) = Self::spawn_memory(cfg)?;
            Ok((sim, Some(host)))
        } else {
            Ok((Self::spawn_pty(cfg)?, None))
        }
    }
}

/// A running simulator. Clones share it; the last one dropped stops it.
#[derive(Clone)]
pub struct SimHandle {
    inner: Arc<Inner>,
}

struct Inner {
    engine: Arc<Mutex<Engine>>,
    ctl: Arc<Control>,
    thread: Mutex<Option<JoinHandle<()>>>,
    device_path: Option<PathBuf>,
    /// Behind an adapter model: its count of the host bytes it took, for
    /// the port a bus opens on a pty ([`SimHandle::pty_opener`]), and for
    /// [`Fault::StuckCount`] (the in-memory line's count too).
    taken: Option<Arc<TakenCount>>,
    write_delay: write_delay::WriteDelayCell,
}

impl SimHandle {
    fn spawn(
        cfg: &SimConfig,
        line: Box<dyn Line>,
        device_path: Option<PathBuf>,
    ) -> Result<Self, SimError> {
        let start = Instant::now();
        let write_delay = write_delay::WriteDelayCell::new(cfg.write_delay);
        let line: Box<dyn Line> = match cfg.adapter {
            AdapterModel::Native => line,
            model => Box::new(adapter::AdapterLine::new(
                line,
                model,
                start,
                cfg.seed,
                write_delay.clone(),
            )),
        };
        let taken = line.taken_count();
        if let Some(count) = taken.as_ref().filter(|_| cfg.stuck_count) {
            count.set_stuck(true);
        }
        let engine = Arc::new(Mutex::new(Engine::new(cfg, start)?));
        let ctl = Arc::new(Control::default());
        let (e, c, rt) = (engine.clone(), ctl.clone(), cfg.realtime);
        let thread = std::thread::Builder::new()
            .name("jointd-sim".into())
            .spawn(move || runner::run(e, line, c, rt))
            .map_err(SimError::Thread)?;
        Ok(Self {
            inner: Arc::new(Inner {
                engine,
                ctl,
                thread: Mutex::new(Some(thread)),
                device_path,
                taken,
                write_delay,
            }),
        })
    }

    fn engine(&self) -> std::sync::MutexGuard<'_, Engine> {
        lock_engine(&self.inner.engine)
    }

    /// The tty a host opens (a stable link; `None` for the memory pipe).
    pub fn device_path(&self) -> Option<PathBuf> {
        self.inner.device_path.clone()
    }

    /// How a bus in this process opens the simulator's pty: by its path,
    /// like hardware, with the adapter model's count of the bytes it took
    /// standing in for a USB-serial driver's output count; `rs485`: ask
    /// for the kernel's RS-485 mode, as a bus configured so would (a pty
    /// refuses it, which is a note). `None` on the in-memory line (its
    /// host end is the port).
    pub fn pty_opener(&self, rs485: bool) -> Option<Opener> {
        let path = self.inner.device_path.clone()?;
        let taken = self.inner.taken.clone();
        Some(Box::new(move |baud| {
            let setup = PortSetup {
                rs485,
                exclusive: false,
            };
            let (port, notes) = TtyPort::open_with(&path, baud, setup)?;
            let port = match &taken {
                Some(count) => port.counted_by(count.clone()),
                None => port,
            };
            Ok((Box::new(port) as Box<dyn Transport>, notes))
        }))
    }

    /// Counters and busy time as of now.
    pub fn stats(&self) -> SimStats {
        self.engine().stats(Instant::now())
    }

    /// Every transmission that left the line, oldest first (bounded ring).
    pub fn frame_log(&self) -> Vec<WireFrame> {
        self.engine().frame_log()
    }

    pub fn clear_frame_log(&self) {
        self.engine().clear_frame_log();
    }

    /// The first device with this id, as it is now.
    pub fn device(&self, id: u8) -> Option<DeviceView> {
        self.devices().into_iter().find(|d| d.id == id)
    }

    /// Every device in bus order (duplicates included).
    pub fn devices(&self) -> Vec<DeviceView> {
        self.engine().views(Instant::now())
    }

    /// Switches a fault on or off. Unplug and replug return once done.
    pub fn inject(&self, fault: Fault) {
        match fault {
            Fault::Unplug => self.inner.ctl.line_op(LineOp::Unplug),
            Fault::Replug => self.inner.ctl.line_op(LineOp::Replug),
            Fault::ClearAll => {
                self.engine().inject(fault, Instant::now());
                self.inner.write_delay.set(None);
                self.stick_count(false);
                self.inner.ctl.line_op(LineOp::Replug);
            }
            Fault::WriteDelay(delay) => self.inner.write_delay.set(delay),
            Fault::StuckCount(on) => self.stick_count(on),
            other => self.engine().inject(other, Instant::now()),
        }
    }

    /// The adapter's count never falls (`on`), or counts again; nothing
    /// on a line without an adapter model (it has no count).
    fn stick_count(&self, on: bool) {
        if let Some(count) = &self.inner.taken {
            count.set_stuck(on);
        }
    }

    /// Real delivery instant minus modelled instant of each reply (ns, late > 0).
    pub fn delivery_errors_ns(&self) -> Vec<i64> {
        self.engine().host.delivery_errors_ns()
    }

    /// Stops the thread (idempotent; also done when the last handle drops).
    pub fn shutdown(&self) {
        self.inner.stop();
    }
}

impl Inner {
    fn stop(&self) {
        self.ctl.request_shutdown();
        let thread = self.thread.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(t) = thread {
            if t.thread().id() != std::thread::current().id() {
                let _ = t.join();
            }
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Names the simulator's line; its engine sits behind a lock a log line
/// should not take.
impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimHandle")
            .field("device_path", &self.inner.device_path)
            .finish_non_exhaustive()
    }
}
