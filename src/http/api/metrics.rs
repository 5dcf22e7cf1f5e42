//! The Prometheus text exposition of `/metrics`, written by hand: every
//! value already lives in the bus snapshots and the WebSocket hub, so a
//! scrape only formats them, and a registry crate (`prometheus-client`)
//! would add a second copy of each counter to keep in step, or a custom
//! collector doing what this file does. `promtool check metrics` judges
//! the output in CI (`.ci/run`); `docs/metrics.md` lists every family, and
//! a test keeps that list and this file in step.
//!
//! Conventions (Prometheus' naming guide): base units (seconds, volts,
//! amperes, hertz, ratios 0..1 named `_ratio`), counters end in `_total`,
//! rates are left to PromQL's `rate()` over the counters, latencies are
//! histograms, states are labels.

//!
//! # Layout
//! - `exposition`: the text format (families, samples, label escaping).
//! - `build_info`, `process`: the build and the process.
//! - `bus`, `devices`: each bus and each device, from its snapshot.
//! - `ws`, `http_requests`, `bridge`: the WebSocket hub, requests by route, ROS 2, recordings
//!   and the live Foxglove view.
//! - this file: the whole exposition in order.

mod bridge;
mod build_info;
mod bus;
mod devices;
mod exposition;
mod http_requests;
mod process;
mod ws;

use std::time::Instant;

use crate::http::state::AppState;
use bridge::{bridge_families, foxglove_families};
use bus::bus_families;
use devices::device_families;
use exposition::{label, Exposition};
use ws::ws_families;

/// Content type of the Prometheus text exposition format.
pub(crate) const PROMETHEUS_TEXT: &str = "text/plain; version=0.0.4; charset=utf-8";

/// The whole exposition of the daemon now.
pub(crate) fn render(state: &AppState) -> String {
    let mut m = Exposition::default();
    build_info::family(&mut m);
    process::families(&mut m);
    m.gauge(
        "jointd_uptime_seconds",
        "Seconds since the daemon started.",
        "",
        state.uptime_s(),
    );
    let now = Instant::now();
    for bus in state.control().readers() {
        let snap = bus.snapshot();
        bus_families(&mut m, &snap);
        m.gauge(
            "jointd_bus_current_limits_owed",
            "Joints whose current limit a grasp or homing lowered and could not write back yet \
             (nothing new moves them until it is).",
            &format!("bus=\"{}\"", label(&snap.name)),
            bus.owed_limits().len() as f64,
        );
        device_families(&mut m, &snap, now);
    }
    ws_families(&mut m, state.ws());
    http_requests::families(&mut m, state);
    bridge_families(&mut m, state);
    foxglove_families(&mut m, state);
    m.render()
}
