//! The API in front of the real bus engine and the simulator on a pty, as
//! the daemon runs it with `--sim`.
#![allow(dead_code)]

use std::time::Duration;

use jointd::bus::{spawn_bus_with, BusConfig, BusHandle, BusSnapshot, BusThread};
use jointd::control::limits::{LimitRule, SoftLimits};
use jointd::http::AppState;
use jointd::sim::{SimConfig, SimHandle, Simulator};

use super::http::{serve, Server};

/// Generous: the machine is loaded; every wait ends on its event.
pub const WAIT: Duration = Duration::from_secs(10);
pub const BAUD: u32 = 500_000;
pub const BUS: &str = "sim0";
pub const REPLY_MARGIN_US: u64 = 50_000;

/// One simulated bus at a time per test binary: each runs two timing-precise
/// threads (simulator and bus owner), and several at once on a loaded
/// 2-core machine would starve each other's wire timing.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

pub struct SimBus {
    _turn: tokio::sync::MutexGuard<'static, ()>,
    pub sim: SimHandle,
    pub handle: BusHandle,
    pub thread: Option<BusThread>,
    pub server: Server,
    /// The state the server runs on (WebSocket sessions driven directly use it).
    pub server_state: AppState,
}

/// `n` joints (ids 1..=n) behind a pty, the engine on it, the API in front;
/// returns once every joint is online.
pub async fn start(n: u8, token: Option<&str>) -> SimBus {
    start_with(n, token, "2.0.1", |_| {}).await
}

/// [`start`] with the simulated devices' firmware (`jointd sim --firmware`
/// syntax, e.g. `1=2.0.8`) and a last word on the bus's config.
pub async fn start_with(
    n: u8,
    token: Option<&str>,
    firmware: &str,
    tweak: impl FnOnce(&mut BusConfig),
) -> SimBus {
    start_sim_with(n, token, firmware, |_| {}, tweak).await
}

/// [`start_with`] with a last word on the simulator's config as well.
pub async fn start_sim_with(
    n: u8,
    token: Option<&str>,
    firmware: &str,
    sim_tweak: impl FnOnce(&mut SimConfig),
    tweak: impl FnOnce(&mut BusConfig),
) -> SimBus {
    let turn = ONE_AT_A_TIME.lock().await;
    let ids: Vec<u8> = (1..=n).collect();
    let mut cfg = SimConfig::new(ids.clone(), BAUD);
    cfg.align_time = Duration::from_millis(50);
    cfg.boot_delay = Duration::from_millis(2);
    cfg.firmware = jointd::sim::Firmware::parse(firmware).expect("firmware spec");
    sim_tweak(&mut cfg);
    let sim = Simulator::spawn_pty(cfg).expect("simulator");
    let path = sim.device_path().expect("pty path");
    let mut bus_cfg = BusConfig::new(BUS, path, BAUD);
    bus_cfg.ids = ids;
    tweak(&mut bus_cfg);
    // A loaded 2-core machine delays pty bytes by milliseconds: give replies
    // that much slack so a late reply is not mistaken for a silent device.
    bus_cfg.timing.reply_margin_us = REPLY_MARGIN_US;
    let opener = sim.pty_opener(bus_cfg.rs485).expect("a pty simulator");
    let (handle, thread) = spawn_bus_with(bus_cfg, opener).expect("bus");
    let limits = SoftLimits::new(vec![LimitRule {
        ids: vec![2],
        min_deg: Some(-45.0),
        max_deg: Some(45.0),
        max_speed_dps: Some(60.0),
        ..Default::default()
    }])
    .expect("limits");
    let state = AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(vec![handle.clone()], limits)),
        token.map(str::to_owned),
    );
    let mut server = serve(state.clone()).await;
    if let Some(t) = token {
        server = server.with_token(t);
    }
    let bus = SimBus {
        _turn: turn,
        sim,
        handle,
        thread: Some(thread),
        server,
        server_state: state,
    };
    let count = usize::from(n);
    bus.wait_snapshot("every joint online", |s| {
        s.devices.values().filter(|d| d.online).count() == count
    })
    .await;
    bus
}

impl SimBus {
    /// Polls move `id` (`GET /api/v1/moves/{id}`) until `ok` holds for its
    /// view; returns that view.
    pub async fn wait_move(
        &self,
        id: u64,
        what: &str,
        ok: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        self.wait_view(&format!("/api/v1/moves/{id}"), WAIT, what, ok)
            .await
    }

    /// Polls `GET path` until `ok` holds for the answer (within `wait`);
    /// returns that answer.
    pub async fn wait_view(
        &self,
        path: &str,
        wait: Duration,
        what: &str,
        ok: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            let view = self.server.get(path).await.ok().clone();
            if ok(&view) {
                return view;
            }
            assert!(
                tokio::time::Instant::now() < deadline,
                "timed out waiting for {what}: {view}"
            );
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }

    /// This rig with an in-memory store for poses and calibrations, and
    /// joints 1..=n enabled and running (homing and calibration need both).
    pub async fn calibrated_and_enabled(self, n: u8) -> SimBus {
        let store = jointd::hands::StateStore::open(Vec::new(), None).expect("store");
        let options = jointd::control::Options {
            hands: Some(std::sync::Arc::new(store)),
            ..Default::default()
        };
        assert!(
            self.server_state.control().set_options(options).is_ok(),
            "options set twice"
        );
        let ids: Vec<u8> = (1..=n).collect();
        self.server
            .post(
                "/api/v1/buses/sim0/control/enable",
                serde_json::json!({ "ids": ids }),
            )
            .await
            .ok();
        for id in ids {
            self.wait_fsm(id, jointd::protocol::status::fsm::RUN).await;
        }
        self
    }

    /// Enables `id` over REST and waits until it runs. A loaded host can
    /// lose the enable's read-back (504 device-timeout) over the pty: asked
    /// again then.
    pub async fn enable_running(&self, id: u8) {
        for attempt in 1..=3 {
            let r = self
                .server
                .post(
                    &format!("/api/v1/buses/sim0/devices/{id}/enable"),
                    serde_json::json!({}),
                )
                .await;
            if r.status.is_success() {
                self.wait_fsm(id, jointd::protocol::status::fsm::RUN).await;
                return;
            }
            assert!(
                r.status.as_u16() == 504 && attempt < 3,
                "enable {id}: {} {}",
                r.status,
                r.body
            );
        }
    }

    /// Waits until a published snapshot satisfies `pred`.
    pub async fn wait_snapshot(&self, what: &str, pred: impl Fn(&BusSnapshot) -> bool) {
        let mut rx = self.handle.watch();
        let waited = tokio::time::timeout(WAIT, rx.wait_for(|s| pred(s))).await;
        assert!(matches!(waited, Ok(Ok(_))), "timed out waiting for: {what}");
    }

    /// Waits until device `id` reports fsm `state` in its INFO_01.
    pub async fn wait_fsm(&self, id: u8, state: u8) {
        self.wait_snapshot(&format!("device {id} in fsm {state}"), |s| {
            s.devices
                .get(&id)
                .and_then(|d| d.info01.as_ref())
                .is_some_and(|(i, _)| i.fsm == state)
        })
        .await;
    }
}

impl Drop for SimBus {
    fn drop(&mut self) {
        if let Some(t) = self.thread.take() {
            t.stop();
        }
        self.sim.shutdown();
    }
}
