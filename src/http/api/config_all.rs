//! Configuration of a whole bus in one request: each parameter to every
//! online device the daemon manages (every online device with
//! `?include_unmanaged=true`), in one frame to id 0xFF where every device
//! runs rev 2.0.8 (SPEC §4.3) and no device would hear it unasked, one
//! write per device otherwise; every device verified and answered for
//! itself, every device left out named with why.

use axum::extract::State;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::config_outcome::{NotWritten, PatchOutcomes, Unverified, Written};
use super::config_params::Param;
use super::config_params::{check_offered, to_config, ConfigPatch};
use super::openapi::{ErrorResponses, TAG_CONFIG};
use crate::bus::handle::{DeviceState, WriteOutcome};
use crate::bus::{BusError, BusSnapshot};
use crate::control::Control;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath, ApiQuery};
use crate::http::state::{AppState, BusPath};
use crate::protocol::ConfigParam;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(patch_bus_config))
}

/// Who a bus-wide PATCH goes to.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct BusPatchQuery {
    /// Also write the online devices the daemon does not manage (not in the
    /// bus's configured `ids`); default false: they are skipped and listed
    /// in `skipped`. Offline devices are skipped either way.
    #[serde(default)]
    #[param(example = false)]
    pub include_unmanaged: bool,
}

/// What a bus-wide PATCH did.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusPatchResult {
    #[schema(example = "sim0")]
    pub bus: String,
    /// `one_frame` (every device runs rev 2.0.8 and every device the bus
    /// knows was asked and is online: each parameter went to id 0xFF once,
    /// then every device was read back) or `per_device` (one write each:
    /// a device runs V2.0.1 or is not known yet, or a skipped device would
    /// have heard the frame to 0xFF); `none` for an empty body.
    #[schema(example = "one_frame")]
    pub method: &'static str,
    /// Every device written: its outcome per parameter (written and
    /// verified, unverified, not written), by id.
    pub devices: Vec<DevicePatch>,
    /// Every device known on the bus and not written, with why.
    pub skipped: Vec<SkippedDevice>,
    /// Devices known on the bus but offline: nothing was sent to them.
    #[schema(example = json!([]))]
    pub offline: Vec<u8>,
}

/// A device a bus-wide PATCH left out.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct SkippedDevice {
    #[schema(example = 7)]
    pub id: u8,
    /// `offline` (it does not answer: a write could not be verified), or
    /// `unmanaged` (not one of the bus's configured `ids`; ask with
    /// `include_unmanaged=true`).
    #[schema(example = "unmanaged")]
    pub reason: &'static str,
}

/// One device's part of a bus-wide PATCH.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DevicePatch {
    #[schema(example = 1)]
    pub id: u8,
    #[serde(flatten)]
    pub outcomes: PatchOutcomes,
}

/// Change parameters of every online device of a bus that the daemon manages, in one request.
///
/// The body is the device PATCH's: any subset of the parameters, in physical units, every value
/// checked before anything is written (and every parameter must exist on every written device's
/// firmware: 422 otherwise). It goes to the online devices the daemon manages (the bus's
/// configured `ids`, or every device of a bus configured with none); `include_unmanaged=true`
/// adds the online devices it does not manage. Offline devices are never written. Where every
/// device written runs rev 2.0.8 firmware and no other device is known on the bus (none skipped,
/// none offline: every device hears a frame to 0xFF), each parameter goes out once, to id 0xFF,
/// and each device is then read back; a device that does not show the value gets a write of its
/// own. Otherwise every device gets its own verified write. The answer lists every device written
/// (`devices`, each parameter verified or not) and every device skipped, with why (`skipped`:
/// `offline` or `unmanaged`). 200 when every device written confirmed every parameter; otherwise
/// a problem (504 `write-unverified`, 502 `verify-mismatch`, ...) whose `partial` is this same
/// answer; 409 `no-device-online` when no device is left to write.
#[utoipa::path(patch, path = "/api/v1/buses/{bus}/config", tag = TAG_CONFIG, params(BusPath, BusPatchQuery),
    request_body(content = ConfigPatch, example = json!({"max_current_a": 2.0})),
    responses((status = 200, description = "Every device written confirmed every parameter", body = BusPatchResult), ErrorResponses))]
async fn patch_bus_config(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiQuery(q): ApiQuery<BusPatchQuery>,
    ApiJson(patch): ApiJson<ConfigPatch>,
) -> ApiResult<Json<BusPatchResult>> {
    let bus = state.control().reader(&p.bus)?;
    let snap = bus.snapshot();
    if let crate::bus::handle::LinkState::Down { reason, .. } = &snap.link {
        return Err(BusError::Down {
            bus: snap.name.clone(),
            reason: reason.clone(),
        }
        .into());
    }
    let (targets, skipped) = addressed(&state, &snap, q.include_unmanaged);
    if targets.is_empty() {
        return Err(nothing_online(&snap.name, &skipped));
    }
    let mut writes = Vec::new();
    for (param, value) in patch.entries() {
        for dev in &targets {
            check_offered(param, dev.dev_id, dev)?;
        }
        writes.push((param, value, to_config(param, value)?));
    }
    let ids: Vec<u8> = targets.iter().map(|d| d.dev_id).collect();
    let (devices, methods, failed) = write_each(state.control(), &snap.name, &ids, writes).await;
    let result = BusPatchResult {
        bus: snap.name.clone(),
        method: match (methods.is_empty(), methods.iter().all(|m| *m)) {
            (true, _) => "none",
            (false, true) => "one_frame",
            (false, false) => "per_device",
        },
        devices,
        offline: skipped
            .iter()
            .filter(|s| s.reason == "offline")
            .map(|s| s.id)
            .collect(),
        skipped,
    };
    match bus_problem(failed, &result) {
        Some(err) => Err(err),
        None => Ok(Json(result)),
    }
}

/// The devices the PATCH writes (online, managed unless `include_unmanaged`),
/// and every other device known on the bus with why it is left out.
fn addressed<'a>(
    state: &AppState,
    snap: &'a BusSnapshot,
    include_unmanaged: bool,
) -> (Vec<&'a DeviceState>, Vec<SkippedDevice>) {
    let mut skipped = Vec::new();
    let mut targets = Vec::new();
    for dev in snap.devices.values() {
        let managed = state.control().managed(&snap.name, dev.dev_id);
        match (dev.online, managed || include_unmanaged) {
            (false, _) => skipped.push(SkippedDevice {
                id: dev.dev_id,
                reason: "offline",
            }),
            (true, false) => skipped.push(SkippedDevice {
                id: dev.dev_id,
                reason: "unmanaged",
            }),
            (true, true) => targets.push(dev),
        }
    }
    (targets, skipped)
}

/// 409 when no device is left to write, saying how to include the unmanaged.
fn nothing_online(bus: &str, skipped: &[SkippedDevice]) -> ApiError {
    let unmanaged = skipped.iter().filter(|s| s.reason == "unmanaged").count();
    let hint = if unmanaged > 0 {
        format!(" ({unmanaged} online device(s) not managed: include_unmanaged=true writes them)")
    } else {
        String::new()
    };
    ApiError::conflict(
        "no-device-online",
        "No device online",
        format!("no managed device of bus {bus} is online: nothing to configure{hint}"),
    )
}

/// Writes each parameter to every device in turn (the bus picks one frame
/// to 0xFF or one per device); after a failure the rest are not sent.
/// Each device's outcomes, whether each parameter went in one frame, the
/// failure that stopped it.
async fn write_each(
    control: &Control,
    bus: &str,
    ids: &[u8],
    writes: Vec<(Param, f64, ConfigParam)>,
) -> (Vec<DevicePatch>, Vec<bool>, Option<ApiError>) {
    let mut devices: Vec<DevicePatch> = ids
        .iter()
        .map(|&id| DevicePatch {
            id,
            outcomes: PatchOutcomes::default(),
        })
        .collect();
    let mut methods = Vec::new();
    let mut failed: Option<ApiError> = None;
    for (param, value, config) in writes {
        let raw = config.index_value().1;
        if failed.is_some() {
            let why = "not sent: the bus failed an earlier parameter".to_string();
            not_written(&mut devices, param, value, raw, &why);
            continue;
        }
        match control.write_all(bus, ids.to_vec(), config).await {
            Ok(outcome) => {
                methods.push(outcome.one_frame);
                let stopped = record(&mut devices, param, value, raw, outcome.per_device);
                if let Some(err) = stopped {
                    failed.get_or_insert(err);
                }
            }
            Err(e) => {
                let err = ApiError::from(e);
                not_written(&mut devices, param, value, raw, &err.problem.detail);
                failed = Some(err.with_field(param.key));
            }
        }
    }
    (devices, methods, failed)
}

/// Every device: `param` not written, with why.
fn not_written(devices: &mut [DevicePatch], param: Param, value: f64, raw: u16, why: &str) {
    for d in devices {
        d.outcomes
            .not_written
            .push(NotWritten::new(param, value, raw, why.to_string()));
    }
}

/// Each device's answer to one parameter; the first failure (other than
/// unverified), as the PATCH's problem.
fn record(
    devices: &mut [DevicePatch],
    param: Param,
    value: f64,
    raw: u16,
    per_device: Vec<(u8, Result<WriteOutcome, BusError>)>,
) -> Option<ApiError> {
    let mut failed = None;
    for (id, result) in per_device {
        let Some(d) = devices.iter_mut().find(|d| d.id == id) else {
            continue;
        };
        match result {
            Ok(w) => d.outcomes.written.push(Written::new(param, value, &w)),
            Err(BusError::Unverified { reason, .. }) => d
                .outcomes
                .unverified
                .push(Unverified::new(param, value, raw, reason)),
            Err(e) => {
                let err = ApiError::from(e);
                let why = err.problem.detail.clone();
                d.outcomes
                    .not_written
                    .push(NotWritten::new(param, value, raw, why));
                failed.get_or_insert(err.with_field(param.key));
            }
        }
    }
    failed
}

/// 200 only when every device confirmed every parameter; else the first
/// failure's problem (or 504 `write-unverified`), with the whole answer as `partial`.
fn bus_problem(failed: Option<ApiError>, result: &BusPatchResult) -> Option<ApiError> {
    let unverified: Vec<String> = result
        .devices
        .iter()
        .flat_map(|d| {
            d.outcomes
                .unverified
                .iter()
                .map(move |u| format!("{} on device {}", u.param, d.id))
        })
        .collect();
    let err = match failed {
        Some(mut err) => {
            let field = err.problem.field.clone().unwrap_or_default();
            err.problem.detail = format!("{field}: {}", err.problem.detail);
            err
        }
        None if unverified.is_empty() => return None,
        None => ApiError::writes_unverified(format!(
            "sent, not confirmed (the devices may or may not have them): {}",
            unverified.join(", ")
        )),
    };
    Some(err.with_partial(serde_json::to_value(result).unwrap_or_default()))
}
