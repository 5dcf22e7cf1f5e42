//! The WebSocket counters over all connections since start.

use super::exposition::Exposition;
use crate::http::hub::WsHub;

/// WebSocket counters over all connections since start.
pub(super) fn ws_families(m: &mut Exposition, ws: &WsHub) {
    let get =
        |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed) as f64;
    m.gauge(
        "jointd_ws_connections",
        "Open WebSocket sessions.",
        "",
        get(&ws.connections),
    );
    m.counter(
        "jointd_ws_dropped_samples_total",
        "Telemetry samples skipped because a client was slow.",
        "",
        get(&ws.dropped_samples),
    );
    m.counter(
        "jointd_ws_dropped_events_total",
        "Events skipped because a client was slow.",
        "",
        get(&ws.dropped_events),
    );
    m.counter(
        "jointd_ws_dropped_replies_total",
        "Replies dropped because a client's reply queue was full.",
        "",
        get(&ws.dropped_replies),
    );
    m.counter(
        "jointd_ws_unsent_replies_total",
        "Replies to requests that never reached the client (it went away).",
        "",
        get(&ws.unsent_replies),
    );
    m.counter(
        "jointd_ws_slow_disconnects_total",
        "Clients closed with 1008 \"too slow\".",
        "",
        get(&ws.slow_disconnects),
    );
    m.histogram(
        "jointd_ws_send_seconds",
        "Writing one message to a client's socket.",
        "",
        &ws.send_latency(),
    );
    // Per connected client; the line goes with the connection.
    for (client, dropped) in ws.client_drops() {
        m.counter(
            "jointd_ws_client_dropped_samples_total",
            "Telemetry samples skipped for this connected client.",
            &format!("client=\"{client}\""),
            dropped as f64,
        );
    }
}
