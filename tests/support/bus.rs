//! Shared fixture of the bus-engine tests: a simulator on a pty opened by
//! path exactly like a USB adapter, a bus owner on it, and waits that end on
//! the awaited state (with a generous deadline for a loaded machine).
#![allow(dead_code)]

use std::sync::Arc;
use std::time::Duration;

use jointd::bus::firmware::FirmwareSetting;
use jointd::bus::handle::BusEvent;
use jointd::bus::{
    spawn_bus_on, spawn_bus_with, BusConfig, BusHandle, BusSnapshot, Setpoint, Targets,
};
use jointd::protocol::status::fsm;
use jointd::sim::{SimConfig, SimHandle, Simulator, WireFrame};

/// Deadline of every wait: they end on the event, this only bounds a failure.
pub const WAIT: Duration = Duration::from_secs(10);
pub const BAUD: u32 = 500_000;
pub const TEST_REPLY_MARGIN_US: u64 = 500_000;

pub struct Rig {
    pub sim: SimHandle,
    pub bus: BusHandle,
    pub thread: Option<jointd::bus::BusThread>,
}

/// A simulator with short align and boot times.
/// True when this host gives a thread the real-time FIFO class (root with
/// a real-time budget, CAP_SYS_NICE, or an RTPRIO limit). A simulated
/// adapter whose timing a test judges the daemon by is wire-accurate only
/// then where its thread reads a pty, or where the daemon dates writes by
/// its replies (blind writes): on a busy host without it the simulator's
/// own stalls look like the path's. Asked from a thread of its own, which
/// ends with the answer.
pub fn realtime_available() -> bool {
    std::thread::spawn(|| jointd::rt::set_fifo(0, 1).is_ok())
        .join()
        .unwrap_or(false)
}

/// [`realtime_available`], saying so on stderr when not: the test that
/// asks returns without judging (the confirmed-write tests on the
/// in-memory line judge the daemon on any host).
pub fn realtime_or_skip(test: &str) -> bool {
    let ok = realtime_available();
    if !ok {
        eprintln!(
            "{test}: skipped: this host refuses the real-time class (no CAP_SYS_NICE or RTPRIO \
             limit), which a simulated adapter needs to keep its timing here"
        );
    }
    ok
}

pub fn sim_config(ids: &[u8], baud: u32) -> SimConfig {
    let mut cfg = SimConfig::new(ids.to_vec(), baud);
    cfg.align_time = Duration::from_millis(50);
    cfg.boot_delay = Duration::from_millis(2);
    cfg
}

/// Simulator on a pty plus a bus owner that opened its path; `ids` empty
/// makes the owner scan 1..=16.
pub fn rig_with(sim_cfg: SimConfig, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let sim = Simulator::spawn_pty(sim_cfg.clone()).expect("spawn simulator");
    bus_on(sim, sim_cfg.baud, tune)
}

/// Like [`rig_with`], on an in-memory pipe instead of a pty: the
/// simulator knows when each host write was made, where a pty's kernel
/// worker may pass bytes on milliseconds late on a loaded machine (a delay
/// a USB-serial driver, which submits the write at once, does not add).
/// For tests that judge the timing of writes on the true wire.
pub fn rig_on_memory(sim_cfg: SimConfig, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let (sim, host) = Simulator::spawn_memory(sim_cfg.clone()).expect("spawn simulator");
    bus_on_memory(sim, Box::new(host), sim_cfg.baud, tune)
}

/// A bus owner on the host end `host` of `sim`'s in-memory line.
fn bus_on_memory(
    sim: SimHandle,
    host: Box<dyn jointd::transport::Transport>,
    baud: u32,
    tune: impl FnOnce(&mut BusConfig),
) -> Rig {
    let mut cfg = BusConfig::new("test", "memory", baud);
    cfg.scan_last = sim.devices().iter().map(|d| d.id).max().unwrap_or(1);
    cfg.timing.reply_margin_us = TEST_REPLY_MARGIN_US;
    firmware_as_configured(&mut cfg, &sim);
    tune(&mut cfg);
    let (bus, thread) = spawn_bus_on(cfg, host).expect("spawn bus");
    Rig {
        sim,
        bus,
        thread: Some(thread),
    }
}

/// [`rig_on_memory`] with a host that wakes `late` after every wait on the
/// port (a slow or busy machine, a virtual CPU woken by its hypervisor):
/// each read that waited returns that much after the bytes came or its
/// timeout ran out.
pub fn rig_on_memory_waking_late(
    sim_cfg: SimConfig,
    late: Duration,
    tune: impl FnOnce(&mut BusConfig),
) -> Rig {
    let (sim, host) = Simulator::spawn_memory(sim_cfg.clone()).expect("spawn simulator");
    let port = WakesLate { inner: host, late };
    bus_on_memory(sim, Box::new(port), sim_cfg.baud, tune)
}

/// A port whose reader wakes late ([`rig_on_memory_waking_late`]).
struct WakesLate<T> {
    inner: T,
    late: Duration,
}

impl<T: jointd::transport::Transport> jointd::transport::Transport for WakesLate<T> {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.inner.write_all(bytes)
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let n = self.inner.read_timeout(buf, timeout)?;
        if !timeout.is_zero() {
            // Spun, not slept: a sleep would add the timer's own lateness.
            let until = std::time::Instant::now() + self.late;
            while std::time::Instant::now() < until {
                std::hint::spin_loop();
            }
        }
        Ok(n)
    }

    fn set_baud(&mut self, baud: u32) -> std::io::Result<()> {
        self.inner.set_baud(baud)
    }

    fn baud(&self) -> u32 {
        self.inner.baud()
    }

    fn discard_input(&mut self) -> std::io::Result<()> {
        self.inner.discard_input()
    }

    fn unsent(&mut self) -> Option<usize> {
        self.inner.unsent()
    }
}

/// Like [`rig_with`], but the bus starts only after every device has
/// announced itself, so it must find them by scanning.
pub fn rig_after_boot(sim_cfg: SimConfig, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let sim = Simulator::spawn_pty(sim_cfg.clone()).expect("spawn simulator");
    wait_until_booted(&sim, sim_cfg.ids.len());
    bus_on(sim, sim_cfg.baud, tune)
}

/// [`rig_after_boot`] on the in-memory line (see [`rig_in_memory`]).
pub fn rig_on_memory_after_boot(sim_cfg: SimConfig, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let (sim, host) = Simulator::spawn_memory(sim_cfg.clone()).expect("spawn simulator");
    wait_until_booted(&sim, sim_cfg.ids.len());
    bus_on_memory(sim, Box::new(host), sim_cfg.baud, tune)
}

fn wait_until_booted(sim: &SimHandle, devices: usize) {
    let deadline = std::time::Instant::now() + WAIT;
    // Polls simulator state (there is no event to wait on); bounded by WAIT.
    while sim.stats().announcements < devices as u64 {
        assert!(std::time::Instant::now() < deadline, "devices never booted");
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn bus_on(sim: SimHandle, baud: u32, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let path = sim.device_path().expect("pty path");
    let mut cfg = BusConfig::new("test", path, baud);
    cfg.scan_last = sim.devices().iter().map(|d| d.id).max().unwrap_or(1);
    // The referee is a thread behind a pty on a loaded machine: when the OS
    // holds it (or the pty's kernel worker) back, a frame reaches the
    // simulated wire tens, at worst hundreds, of ms after it was written.
    // Wait long enough that a reply given up on is really gone (on hardware
    // the default is ample). Tests avoid absent ids, which pay this wait.
    cfg.timing.reply_margin_us = TEST_REPLY_MARGIN_US;
    firmware_as_configured(&mut cfg, &sim);
    tune(&mut cfg);
    let opener = sim.pty_opener(cfg.rs485).expect("a pty simulator");
    let (bus, thread) = spawn_bus_with(cfg, opener).expect("spawn bus");
    Rig {
        sim,
        bus,
        thread: Some(thread),
    }
}

/// The devices' firmware as a config file would say it: a probe of a
/// silent V2.0.1 device pays the test margin, like an absent id. Detection
/// has its own tests (api_firmware, the scheduler's).
fn firmware_as_configured(cfg: &mut BusConfig, sim: &SimHandle) {
    for d in sim.devices() {
        cfg.firmware_by_id
            .insert(d.id.to_string(), FirmwareSetting::Fixed(d.firmware));
    }
}

pub fn rig(ids: &[u8]) -> Rig {
    rig_with(sim_config(ids, BAUD), |_| {})
}

/// [`rig`] on the in-memory line, which dates each host write when it was
/// made: the referee for tests that count collisions on a loaded host. Over
/// a pty the simulator sees a write only when the kernel's worker and its
/// own thread get the CPU. Held back, it reads writes made far apart as one
/// burst (requests sent half a second apart, each after the last reply was
/// given up on; an e-stop a frame after a reply was due, behind the poll) and
/// puts them on the simulated wire together, a collision no UART would make.
pub fn rig_in_memory(ids: &[u8]) -> Rig {
    rig_on_memory(sim_config(ids, BAUD), |_| {})
}

impl Rig {
    /// Waits until the bus snapshot satisfies `pred`; panics with the last
    /// snapshot after [`WAIT`].
    pub async fn until(&self, what: &str, pred: impl Fn(&BusSnapshot) -> bool) -> Arc<BusSnapshot> {
        let mut rx = self.bus.watch();
        let waited = tokio::time::timeout(WAIT, rx.wait_for(|s| pred(s))).await;
        match waited {
            Ok(Ok(snap)) => snap.clone(),
            _ => panic!(
                "timed out waiting for {what}; {}",
                summary(&self.bus.snapshot())
            ),
        }
    }

    pub async fn online(&self, n: usize) -> Arc<BusSnapshot> {
        self.until(&format!("{n} devices online"), |s| {
            s.devices.values().filter(|d| d.online).count() == n
        })
        .await
    }

    /// Host frames the simulator logged, collided ones included.
    pub fn host_frames(&self) -> Vec<WireFrame> {
        self.sim
            .frame_log()
            .into_iter()
            .filter(|f| f.from_host)
            .collect()
    }

    /// Host frames that started on the wire at or after `mark`.
    pub fn host_frames_since(&self, mark: std::time::Instant) -> Vec<WireFrame> {
        self.host_frames()
            .into_iter()
            .filter(|f| f.start >= mark)
            .collect()
    }

    /// Stops the bus owner and starts a new one on the same simulator, as
    /// a daemon restart would (the devices keep their state).
    pub fn restart_bus(&mut self, tune: impl FnOnce(&mut BusConfig)) {
        self.stop();
        let path = self.sim.device_path().expect("pty path");
        let mut cfg = BusConfig::new("test", path, BAUD);
        cfg.ids = self.sim.devices().iter().map(|d| d.id).collect();
        cfg.timing.reply_margin_us = TEST_REPLY_MARGIN_US;
        firmware_as_configured(&mut cfg, &self.sim);
        tune(&mut cfg);
        let opener = self.sim.pty_opener(cfg.rs485).expect("a pty simulator");
        let (bus, thread) = spawn_bus_with(cfg, opener).expect("spawn bus");
        self.bus = bus;
        self.thread = Some(thread);
    }

    pub fn stop(&mut self) {
        if let Some(t) = self.thread.take() {
            t.stop();
        }
    }
}

/// Waits for an event matching `pred` on `rx`.
pub async fn event(
    rx: &mut tokio::sync::broadcast::Receiver<BusEvent>,
    what: &str,
    pred: impl Fn(&BusEvent) -> bool,
) -> BusEvent {
    let wait = async {
        loop {
            match rx.recv().await {
                Ok(ev) if pred(&ev) => return ev,
                Ok(_) | Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                Err(e) => panic!("event channel closed: {e}"),
            }
        }
    };
    tokio::time::timeout(WAIT, wait)
        .await
        .unwrap_or_else(|_| panic!("timed out waiting for event: {what}"))
}

/// A short account of a snapshot for failure messages.
pub fn summary(s: &BusSnapshot) -> String {
    let devices: Vec<String> = s
        .devices
        .values()
        .map(|d| format!("{}{}", d.dev_id, if d.online { "" } else { "(off)" }))
        .collect();
    format!(
        "link {:?}, baud {}, devices [{}], counters {:?}",
        s.link,
        s.baud,
        devices.join(" "),
        s.counters
    )
}

/// 20000 rpm, the vendor's recommended speed limit (Q15).
pub const SPEED: i16 = 13_106;

pub fn target(deg: f64) -> Setpoint {
    Setpoint {
        pos_ref: (deg * 128.0).round() as i16,
        spd_ref: SPEED,
    }
}

impl Rig {
    /// Enables every device and waits until each reports run (INFO_01).
    pub async fn enable_all(&self, n: usize) {
        self.bus.enable(Targets::All).await.expect("enable");
        self.until("all running", |s| {
            s.devices
                .values()
                .filter(|d| d.info01.is_some_and(|(i, _)| i.fsm == fsm::RUN))
                .count()
                == n
        })
        .await;
    }

    /// Waits until device `id`'s telemetry angle is within 1° of `deg`.
    pub async fn reaches(&self, id: u8, deg: f64) {
        self.until(&format!("device {id} at {deg}°"), |s| {
            s.devices
                .get(&id)
                .and_then(|d| d.info02)
                .is_some_and(|(i, _)| (f64::from(i.angle) / 128.0 - deg).abs() < 1.0)
        })
        .await;
    }

    /// Waits (bounded) until the simulator's view satisfies `pred`: the
    /// simulator publishes no events, so this polls it.
    pub fn sim_until(&self, what: &str, pred: impl Fn(&SimHandle) -> bool) {
        let deadline = std::time::Instant::now() + WAIT;
        while !pred(&self.sim) {
            assert!(
                std::time::Instant::now() < deadline,
                "timed out waiting for {what}"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Rig {
    /// Asserts the simulator saw no collision, showing the frames around any.
    pub fn assert_no_collisions(&self) {
        let stats = self.sim.stats();
        if stats.collisions > 0 {
            let context = jointd::sim::collision_context(&self.sim.frame_log());
            panic!(
                "{} collision(s):\n{}\n{}",
                stats.collisions,
                context.join("\n"),
                summary(&self.bus.snapshot())
            );
        }
    }
}

/// A client streaming every joint's target once per `period` on its own
/// thread (a ramp from 0° at 1/128° per write), as a teleoperation client
/// would; stops when dropped.
pub struct TargetStream {
    stop: Arc<std::sync::atomic::AtomicBool>,
    join: Option<std::thread::JoinHandle<u64>>,
}

impl TargetStream {
    pub fn start(bus: BusHandle, ids: Vec<u8>, period: Duration) -> Self {
        use std::sync::atomic::{AtomicBool, Ordering};
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let join = std::thread::spawn(move || {
            let mut next = std::time::Instant::now();
            let mut n: i16 = 0;
            let mut writes = 0u64;
            while !flag.load(Ordering::Acquire) {
                let sp = Setpoint {
                    pos_ref: n,
                    spd_ref: 13_106,
                };
                let targets: Vec<(u8, Setpoint)> = ids.iter().map(|id| (*id, sp)).collect();
                bus.set_targets(&targets);
                writes += 1;
                n = n.wrapping_add(1).max(0);
                next += period;
                let now = std::time::Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                } else {
                    next = now;
                }
            }
            writes
        });
        Self {
            stop,
            join: Some(join),
        }
    }
}

impl TargetStream {
    /// Stops the stream; how many writes it made.
    pub fn finish(mut self) -> u64 {
        self.halt()
    }

    fn halt(&mut self) -> u64 {
        self.stop.store(true, std::sync::atomic::Ordering::Release);
        self.join
            .take()
            .map_or(0, |join| join.join().unwrap_or_default())
    }
}

impl Drop for TargetStream {
    fn drop(&mut self) {
        self.halt();
    }
}
