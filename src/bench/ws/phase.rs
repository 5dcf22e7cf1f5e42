//! One measured window of the WebSocket bench, as its report reads it.

use crate::bench::analysis::Analysis;

/// One measured window.
pub(super) struct Phase {
    pub(super) occupancy: f64,
    pub(super) collisions: u64,
    pub(super) analysis: Analysis,
    pub(super) cpu_daemon: f64,
    pub(super) cpu_clients: f64,
    pub(super) rss_mb: f64,
    /// Telemetry messages/s per client (min, mean) and samples they skipped.
    pub(super) telemetry: Option<(f64, f64, u64)>,
    /// Mean size of a telemetry message, bytes.
    pub(super) telemetry_len: Option<f64>,
}
