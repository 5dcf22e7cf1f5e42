//! Buses: list, state (link, baud, stats), scan an id range, change baud,
//! and the raw frame log (the vendor tool's RX/TX view).

use std::time::UNIX_EPOCH;

use axum::extract::State;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_BUSES};
use crate::bus::handle::{LinkState, FRAME_LOG_LEN};
use crate::bus::BusSnapshot;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath, ApiQuery};
use crate::http::state::{device_id, AppState, BusPath};
use crate::protocol::frame_json::frame_to_json;
use crate::protocol::{BaudLevel, Frame, MAX_DEVICE_ID};

/// Frames the log view returns when no `limit` is given.
const DEFAULT_FRAME_LIMIT: i64 = 50;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_buses))
        .routes(routes!(get_bus))
        .routes(routes!(scan))
        .routes(routes!(set_baud))
        .routes(routes!(frames))
}

/// A bus's state and stats.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusView {
    #[schema(example = "sim0")]
    pub name: String,
    #[schema(example = "/dev/ttyUSB0")]
    pub path: String,
    #[schema(example = 500000)]
    pub baud: u32,
    /// `opening`, `up` or `down`.
    #[schema(example = "up")]
    pub link: &'static str,
    /// Why the bus is down, when it is.
    pub down_reason: Option<String>,
    pub retry_in_ms: Option<u64>,
    #[schema(example = 16)]
    pub devices_known: usize,
    #[schema(example = 16)]
    pub devices_online: usize,
    /// One-shot requests waiting for the bus.
    #[schema(example = 0)]
    pub queue_depth: usize,
    /// Polls written blind behind a USB adapter whose reply is still on its way (0 on a native line).
    #[schema(example = 0)]
    pub polls_in_flight: usize,
    /// Monotonic counters since start (frames by kind, CRC errors, timeouts, retries, ...).
    #[schema(value_type = Object, example = json!({"frames_rx": 10432, "crc_errors": 0, "timeouts": 3}))]
    pub counters: serde_json::Value,
    /// Rates over the last statistics window (~1 s): frames/s by kind, wire
    /// utilisation as the daemon sees it, setpoint age percentiles.
    #[schema(value_type = Object, example = json!({"window_s": 1.0, "frames_tx_per_s": 2310.5,
        "wire_utilisation": 0.97, "setpoint_age_p99_us": 1800}))]
    pub rates: serde_json::Value,
    /// What opening the port found worth telling (e.g. an FTDI latency timer and its fix).
    pub port_notes: Vec<String>,
    /// The USB adapter timing the bus plans for: `native` (a pty, a UART),
    /// `ftdi:MS` (MS = its latency timer in effect), `ch340`, `cp2102`,
    /// `ft232h:MS`; from the bus's `adapter` setting or sysfs.
    #[schema(example = "ftdi:1")]
    pub adapter: String,
    /// One poll's round trip as the host lives it on that adapter
    /// (USB frame wait, both frames, turnaround, the adapter's hold), µs.
    #[schema(example = 2900)]
    pub transaction_us: u64,
    /// Behind a USB adapter (absent on a native line): the pipeline's
    /// mode (`pipelined`, `guarded`, `lockstep`), its guard and the
    /// reason of its last change. It backs off when collisions leave
    /// garbled bytes or lost replies, and steps back after a clean while.
    pub usb_pipeline: Option<crate::bus::usb::guard::UsbPipelineView>,
}

impl BusView {
    pub(crate) fn new(snap: &BusSnapshot) -> Self {
        let (down_reason, retry_in_ms) = match &snap.link {
            LinkState::Down {
                reason,
                retry_in_ms,
            } => (Some(reason.clone()), Some(*retry_in_ms)),
            _ => (None, None),
        };
        Self {
            name: snap.name.clone(),
            path: snap.path.clone(),
            baud: snap.baud,
            link: snap.link.name(),
            down_reason,
            retry_in_ms,
            devices_known: snap.devices.len(),
            devices_online: snap.devices.values().filter(|d| d.online).count(),
            queue_depth: snap.queue_depth,
            polls_in_flight: snap.polls_in_flight,
            counters: serde_json::to_value(&snap.counters).unwrap_or_default(),
            rates: serde_json::to_value(&snap.rates).unwrap_or_default(),
            port_notes: snap.port_notes.clone(),
            adapter: snap.adapter.clone(),
            transaction_us: snap.transaction_us,
            usb_pipeline: snap.usb_pipeline.clone(),
        }
    }
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusList {
    pub buses: Vec<BusView>,
}

/// An id range to scan, inclusive.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct ScanRequest {
    #[schema(minimum = 1, maximum = 159, example = 1)]
    pub first: i64,
    #[schema(minimum = 1, maximum = 159, example = 16)]
    pub last: i64,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ScanResult {
    #[schema(example = "sim0")]
    pub bus: String,
    /// Ids that answered INFO_01.
    #[schema(example = json!([1, 2, 3]))]
    pub found: Vec<u8>,
}

#[derive(Debug, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct BaudRequest {
    /// One of the device baud levels.
    #[schema(example = 500000, minimum = 19200, maximum = 500000)]
    pub baud: i64,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct FramesQuery {
    /// How many of the latest frames, 1..=512 (default 50).
    #[param(minimum = 1, maximum = 512, example = 20)]
    pub limit: Option<i64>,
}

/// One frame seen on the wire.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct FrameView {
    /// Wall-clock time, seconds since the Unix epoch.
    #[schema(example = 1732200000.123)]
    pub at: f64,
    /// `tx` (host to devices) or `rx`.
    #[schema(example = "rx")]
    pub direction: &'static str,
    #[schema(example = "55 AA 00 14 00 01 01 00 07 00 80 51 C0 16 0D 06 4C 2B 00 00")]
    pub hex: String,
    /// The frame decoded (field names as in `jointd frame decode`).
    #[schema(value_type = Object)]
    pub decoded: serde_json::Value,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct FrameLog {
    pub frames: Vec<FrameView>,
}

/// List every bus with its state and stats.
///
/// Each bus with its serial path, baud, link state (and why it is down), known and online devices,
/// queue depth and counters.
#[utoipa::path(get, path = "/api/v1/buses", tag = TAG_BUSES,
    responses((status = 200, description = "Every configured bus", body = BusList), ErrorResponses))]
async fn list_buses(State(state): State<AppState>) -> Json<BusList> {
    let buses = state
        .control()
        .readers()
        .map(|b| BusView::new(&b.snapshot()))
        .collect();
    Json(BusList { buses })
}

/// One bus's state: link, baud, stats.
///
/// The bus's serial path, baud, link state (and why it is down, with the next retry), devices known
/// and online, queue depth and the frame, error and timing counters.
#[utoipa::path(get, path = "/api/v1/buses/{bus}", tag = TAG_BUSES, params(BusPath),
    responses((status = 200, description = "The bus", body = BusView), ErrorResponses))]
async fn get_bus(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
) -> ApiResult<Json<BusView>> {
    Ok(Json(BusView::new(
        &state.control().reader(&p.bus)?.snapshot(),
    )))
}

/// Scan an id range: poll INFO_01 of each id; devices that answer join the bus.
///
/// Polls INFO_01 of every id in `first..=last` between the bus's regular work; devices that answer
/// join the bus and are polled from then on. Nothing is enabled or moved.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/scan", tag = TAG_BUSES, params(BusPath),
    request_body(content = ScanRequest, example = json!({"first": 1, "last": 16})),
    responses((status = 200, description = "Ids that answered", body = ScanResult), ErrorResponses))]
async fn scan(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<ScanRequest>,
) -> ApiResult<Json<ScanResult>> {
    state.control().reader(&p.bus)?;
    let first = device_id("first", req.first)?;
    let last = device_id("last", req.last)?;
    if first > last {
        return Err(ApiError::out_of_range(
            "last",
            req.last as f64,
            (f64::from(first), f64::from(MAX_DEVICE_ID)),
            "",
        ));
    }
    let found = state.control().scan(&p.bus, first, last).await?;
    Ok(Json(ScanResult { bus: p.bus, found }))
}

/// Change the baud of every device on the bus, then of the port.
///
/// Writes the new baud level to every known device (each confirms with RES), then switches the
/// port. The level is RAM until persisted with
/// `config/persist`.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/baud", tag = TAG_BUSES, params(BusPath),
    request_body(content = BaudRequest, example = json!({"baud": 500000})),
    responses((status = 200, description = "The bus now runs at this baud", body = BaudRequest),
        ErrorResponses))]
async fn set_baud(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<BaudRequest>,
) -> ApiResult<Json<BaudRequest>> {
    state.control().reader(&p.bus)?;
    let level = u32::try_from(req.baud)
        .ok()
        .and_then(BaudLevel::from_baud)
        .ok_or_else(|| {
            let allowed: Vec<String> = BaudLevel::ALL
                .iter()
                .map(|l| l.baud().to_string())
                .collect();
            ApiError::invalid(
                "baud",
                format!(
                    "baud {} is not a device baud level; allowed: {}",
                    req.baud,
                    allowed.join(", ")
                ),
            )
        })?;
    state.control().set_baud(&p.bus, level).await?;
    Ok(Json(BaudRequest {
        baud: i64::from(level.baud()),
    }))
}

/// The latest frames seen on the wire, oldest first, decoded.
///
/// The frame log of the bus: each frame's direction, wire time, raw hex and decoded fields, oldest
/// first. `limit` bounds the count; the dashboard's frame log reads it.
#[utoipa::path(get, path = "/api/v1/buses/{bus}/frames", tag = TAG_BUSES,
    params(BusPath, FramesQuery),
    responses((status = 200, description = "Raw frame log", body = FrameLog), ErrorResponses))]
async fn frames(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiQuery(q): ApiQuery<FramesQuery>,
) -> ApiResult<Json<FrameLog>> {
    let bus = state.control().reader(&p.bus)?;
    let limit = q.limit.unwrap_or(DEFAULT_FRAME_LIMIT);
    if !(1..=FRAME_LOG_LEN as i64).contains(&limit) {
        return Err(ApiError::out_of_range(
            "limit",
            limit as f64,
            (1.0, FRAME_LOG_LEN as f64),
            "frames",
        ));
    }
    let frames = bus
        .recent_frames(limit as usize)
        .into_iter()
        .map(|f| FrameView {
            at: f
                .at
                .duration_since(UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
            direction: if f.tx { "tx" } else { "rx" },
            hex: crate::http::telemetry::hex(&f.bytes),
            decoded: Frame::decode(&f.bytes)
                .map(|fr| frame_to_json(&fr))
                .unwrap_or_else(|e| serde_json::json!({"kind": "garbage", "error": e.to_string()})),
        })
        .collect();
    Ok(Json(FrameLog { frames }))
}
