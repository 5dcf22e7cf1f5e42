//! `/healthz` (the process is up), `/readyz` (every bus is up) and
//! `/metrics` (Prometheus text: the bus counters and per-joint gauges).

use std::fmt::Write as _;
use std::time::Instant;

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_HEALTH};
use crate::bus::handle::LinkState;
use crate::bus::BusSnapshot;
use crate::http::error::{ApiError, ApiResult};
use crate::http::state::AppState;

/// Content type of the Prometheus text exposition format.
const PROMETHEUS_TEXT: &str = "text/plain; version=0.0.4; charset=utf-8";

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(healthz))
        .routes(routes!(readyz))
        .routes(routes!(metrics))
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Health {
    #[schema(example = "ok")]
    pub status: &'static str,
    #[schema(example = "0.1.0")]
    pub version: &'static str,
    #[schema(example = 12.5)]
    pub uptime_s: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusReadiness {
    #[schema(example = "sim0")]
    pub bus: String,
    /// `opening`, `up` or `down`.
    #[schema(example = "up")]
    pub link: &'static str,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Readiness {
    #[schema(example = true)]
    pub ready: bool,
    pub buses: Vec<BusReadiness>,
}

pub(crate) fn link_name(link: &LinkState) -> &'static str {
    match link {
        LinkState::Opening => "opening",
        LinkState::Up => "up",
        LinkState::Down { .. } => "down",
    }
}

/// The process is up (never needs a token).
///
/// Answers as long as the process runs, whatever the buses do; for a container's liveness probe.
/// Never needs a token and skips the Host check so probes from outside work.
#[utoipa::path(get, path = "/healthz", tag = TAG_HEALTH, security(()),
    responses((status = 200, description = "The process is up", body = Health)))]
async fn healthz(State(state): State<AppState>) -> Json<Health> {
    Json(Health {
        status: "ok",
        version: env!("CARGO_PKG_VERSION"),
        uptime_s: state.uptime_s(),
    })
}

/// Every configured bus is up (503 otherwise, with each bus's link state).
///
/// Ready means every configured bus has its port open and its owner running. A bus that is down
/// (device unplugged, port missing) makes it 503 with each bus's link state in `partial`; for a
/// readiness probe or a start-up script that waits for the hardware.
#[utoipa::path(get, path = "/readyz", tag = TAG_HEALTH,
    responses((status = 200, description = "Every bus is up", body = Readiness), ErrorResponses))]
async fn readyz(State(state): State<AppState>) -> ApiResult<Json<Readiness>> {
    let buses: Vec<BusReadiness> = state
        .buses()
        .map(|b| BusReadiness {
            bus: b.name().to_owned(),
            link: link_name(&b.snapshot().link),
        })
        .collect();
    let down: Vec<&str> = buses
        .iter()
        .filter(|b| b.link != "up")
        .map(|b| b.bus.as_str())
        .collect();
    if down.is_empty() {
        return Ok(Json(Readiness { ready: true, buses }));
    }
    let detail = format!("bus(es) not up: {}", down.join(", "));
    let partial = serde_json::to_value(&buses).unwrap_or_default();
    Err(ApiError::not_ready(detail).with_partial(partial))
}

/// Prometheus text: bus counters, link state, per-joint gauges.
///
/// The Prometheus text exposition of every counter and gauge: frames per kind, CRC errors,
/// timeouts, collisions, queue depths, per-joint telemetry, WebSocket clients. Scrape it;
/// `docs/metrics.md` lists the families.
#[utoipa::path(get, path = "/metrics", tag = TAG_HEALTH,
    responses((status = 200, description = "Prometheus text exposition format",
        content_type = "text/plain", body = String,
        example = "jointd_bus_up{bus=\"sim0\"} 1\njointd_bus_frames_rx_total{bus=\"sim0\"} 10432\n"),
        ErrorResponses))]
async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    let mut m = Metrics::default();
    m.gauge("jointd_uptime_seconds", String::new(), state.uptime_s());
    let now = Instant::now();
    for bus in state.buses() {
        let snap = bus.snapshot();
        bus_metrics(&mut m, &snap);
        device_metrics(&mut m, &snap, now);
    }
    ws_metrics(&mut m, state.ws());
    ([(header::CONTENT_TYPE, PROMETHEUS_TEXT)], m.render())
}

/// Samples grouped by metric family (the text format wants each family's
/// lines together, with one `# TYPE` line).
#[derive(Default)]
struct Metrics {
    families: Vec<(String, &'static str, Vec<String>)>,
}

impl Metrics {
    fn push(&mut self, name: &str, kind: &'static str, labels: String, value: f64) {
        let line = if labels.is_empty() {
            format!("{name} {value}")
        } else {
            format!("{name}{{{labels}}} {value}")
        };
        match self.families.iter_mut().find(|(n, _, _)| n == name) {
            Some((_, _, lines)) => lines.push(line),
            None => self.families.push((name.to_owned(), kind, vec![line])),
        }
    }

    fn gauge(&mut self, name: &str, labels: String, value: f64) {
        self.push(name, "gauge", labels, value);
    }

    fn render(&self) -> String {
        let mut out = String::new();
        for (name, kind, lines) in &self.families {
            let _ = writeln!(out, "# TYPE {name} {kind}");
            for line in lines {
                let _ = writeln!(out, "{line}");
            }
        }
        out
    }
}

/// A label value with `\`, `"` and newlines escaped.
fn label(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

fn bus_metrics(m: &mut Metrics, snap: &BusSnapshot) {
    let l = format!("bus=\"{}\"", label(&snap.name));
    let online = snap.devices.values().filter(|d| d.online).count();
    let up = u8::from(snap.link == LinkState::Up);
    m.gauge("jointd_bus_up", l.clone(), f64::from(up));
    m.gauge("jointd_bus_baud", l.clone(), f64::from(snap.baud));
    m.gauge("jointd_bus_queue_depth", l.clone(), snap.queue_depth as f64);
    m.gauge("jointd_bus_devices_online", l.clone(), online as f64);
    // Every counter the engine keeps, by its field name: new counters
    // appear here without a change to this file.
    if let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(&snap.counters) {
        for (name, value) in fields {
            if let Some(v) = value.as_u64() {
                let family = format!("jointd_bus_{name}_total");
                m.push(&family, "counter", l.clone(), v as f64);
            }
        }
    }
    // Rates over the engine's last window, as gauges by field name.
    if let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(&snap.rates) {
        for (name, value) in fields {
            if let Some(v) = value.as_f64() {
                m.gauge(&format!("jointd_bus_{name}"), l.clone(), v);
            }
        }
    }
}

/// WebSocket counters over all connections since start.
fn ws_metrics(m: &mut Metrics, ws: &crate::http::hub::WsHub) {
    let get =
        |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed) as f64;
    m.gauge("jointd_ws_connections", String::new(), get(&ws.connections));
    // Telemetry samples skipped because a client was slow.
    m.push(
        "jointd_ws_dropped_samples_total",
        "counter",
        String::new(),
        get(&ws.dropped_samples),
    );
    m.push(
        "jointd_ws_dropped_events_total",
        "counter",
        String::new(),
        get(&ws.dropped_events),
    );
    // Replies dropped because a client's reply queue was full.
    m.push(
        "jointd_ws_dropped_replies_total",
        "counter",
        String::new(),
        get(&ws.dropped_replies),
    );
    // Replies to requests that never reached the client (it went away).
    m.push(
        "jointd_ws_unsent_replies_total",
        "counter",
        String::new(),
        get(&ws.unsent_replies),
    );
    // Clients closed with 1008 "too slow".
    m.push(
        "jointd_ws_slow_disconnects_total",
        "counter",
        String::new(),
        get(&ws.slow_disconnects),
    );
    // Samples skipped per connected client (gone with its connection).
    for (client, dropped) in ws.client_drops() {
        m.push(
            "jointd_ws_client_dropped_samples_total",
            "counter",
            format!("client=\"{client}\""),
            dropped as f64,
        );
    }
}

fn device_metrics(m: &mut Metrics, snap: &BusSnapshot, now: Instant) {
    let bus = label(&snap.name);
    for dev in snap.devices.values() {
        let l = format!("bus=\"{bus}\",id=\"{}\"", dev.dev_id);
        m.gauge(
            "jointd_device_online",
            l.clone(),
            f64::from(u8::from(dev.online)),
        );
        m.gauge("jointd_device_control_hz", l.clone(), dev.control_hz);
        m.gauge("jointd_device_telemetry_hz", l.clone(), dev.telemetry_hz);
        // Power cuts and reboots the daemon detected (announcement or state drop).
        m.push(
            "jointd_device_resets_total",
            "counter",
            l.clone(),
            dev.resets as f64,
        );
        if let Some((i, at)) = &dev.info01 {
            let age = now.saturating_duration_since(*at).as_secs_f64();
            m.gauge("jointd_device_fsm", l.clone(), f64::from(i.fsm));
            m.gauge("jointd_device_fault_code", l.clone(), f64::from(i.err_code));
            m.gauge("jointd_device_temperature_celsius", l.clone(), i.temp_c());
            m.gauge("jointd_device_bus_voltage_volts", l.clone(), i.vbus_v());
            m.gauge("jointd_device_status_age_seconds", l.clone(), age);
        }
        if let Some((i, at)) = &dev.info02 {
            let age = now.saturating_duration_since(*at).as_secs_f64();
            let q = crate::protocol::units::current_a(i.q_cur);
            m.gauge("jointd_device_angle_degrees", l.clone(), i.angle_deg());
            m.gauge("jointd_device_q_current_amperes", l.clone(), q);
            m.gauge("jointd_device_telemetry_age_seconds", l, age);
        }
    }
}
