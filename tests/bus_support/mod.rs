//! Shared fixture of the bus-engine tests: a simulator on a pty opened by
//! path exactly like a USB adapter, a bus owner on it, and waits that end on
//! the awaited state (with a generous deadline for a loaded machine).
#![allow(dead_code)]

use std::sync::Arc;
use std::time::Duration;

use jointd::bus::handle::BusEvent;
use jointd::bus::{spawn_bus, BusConfig, BusHandle, BusSnapshot};
use jointd::sim::{SimConfig, SimHandle, Simulator, WireFrame};

/// Deadline of every wait: they end on the event, this only bounds a failure.
pub const WAIT: Duration = Duration::from_secs(10);
pub const BAUD: u32 = 500_000;
pub const TEST_REPLY_MARGIN_US: u64 = 20_000;

pub struct Rig {
    pub sim: SimHandle,
    pub bus: BusHandle,
    pub thread: Option<jointd::bus::BusThread>,
}

/// A simulator with short align and boot times.
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

/// Like [`rig_with`], but the bus starts only after every device has
/// announced itself, so it must find them by scanning.
pub fn rig_after_boot(sim_cfg: SimConfig, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let n = sim_cfg.ids.len() as u64;
    let sim = Simulator::spawn_pty(sim_cfg.clone()).expect("spawn simulator");
    let deadline = std::time::Instant::now() + WAIT;
    // Polls simulator state (there is no event to wait on); bounded by WAIT.
    while sim.stats().announcements < n {
        assert!(std::time::Instant::now() < deadline, "devices never booted");
        std::thread::sleep(Duration::from_millis(1));
    }
    bus_on(sim, sim_cfg.baud, tune)
}

fn bus_on(sim: SimHandle, baud: u32, tune: impl FnOnce(&mut BusConfig)) -> Rig {
    let path = sim.device_path().expect("pty path");
    let mut cfg = BusConfig::new("test", path, baud);
    cfg.scan_last = 16;
    // The referee is a thread on a loaded machine: when the OS holds it back
    // for milliseconds, a reply arrives that late. Wait long enough that a
    // reply given up on is really gone (on hardware, the default is ample).
    cfg.timing.reply_margin_us = TEST_REPLY_MARGIN_US;
    tune(&mut cfg);
    let (bus, thread) = spawn_bus(cfg).expect("spawn bus");
    Rig {
        sim,
        bus,
        thread: Some(thread),
    }
}

pub fn rig(ids: &[u8]) -> Rig {
    rig_with(sim_config(ids, BAUD), |_| {})
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
