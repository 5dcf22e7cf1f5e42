//! Configuration of a whole bus in one request: each parameter to every
//! online device, in one frame to id 0xFF where every device runs rev 2.0.8
//! (SPEC §4.3), one write per device otherwise; every device verified and
//! answered for itself.

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::config_outcome::{NotWritten, PatchOutcomes, Unverified, Written};
use super::config_params::{check_offered, to_config, ConfigPatch};
use super::openapi::{ErrorResponses, TAG_CONFIG};
use crate::bus::BusError;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::{AppState, BusPath};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(patch_bus_config))
}

/// What a bus-wide PATCH did.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct BusPatchResult {
    #[schema(example = "sim0")]
    pub bus: String,
    /// `one_frame` (every device runs rev 2.0.8: each parameter went to id
    /// 0xFF once, then every device was read back) or `per_device` (at
    /// least one device runs V2.0.1 or is not known yet: one write each);
    /// `none` for an empty body.
    #[schema(example = "one_frame")]
    pub method: &'static str,
    /// Each online device's outcome, by id.
    pub devices: Vec<DevicePatch>,
    /// Devices known on the bus but offline: nothing was sent to them
    /// individually (a frame to 0xFF reaches them if they are listening).
    #[schema(example = json!([]))]
    pub offline: Vec<u8>,
}

/// One device's part of a bus-wide PATCH.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DevicePatch {
    #[schema(example = 1)]
    pub id: u8,
    #[serde(flatten)]
    pub outcomes: PatchOutcomes,
}

/// Change parameters of every online device of a bus in one request.
///
/// The body is the device PATCH's: any subset of the parameters, in physical units, every value
/// checked before anything is written (and every parameter must exist on every online device's
/// firmware: 422 otherwise). Where every online device runs rev 2.0.8 firmware, each parameter
/// goes out once, to id 0xFF, and each device is then read back; a device that does not show the
/// value gets a write of its own. Otherwise every device gets its own verified write. 200 when
/// every device confirmed every parameter; otherwise a problem (504 `write-unverified`, 502
/// `verify-mismatch`, ...) whose `partial` is this same per-device answer.
#[utoipa::path(patch, path = "/api/v1/buses/{bus}/config", tag = TAG_CONFIG, params(BusPath),
    request_body(content = ConfigPatch, example = json!({"max_current_a": 2.0})),
    responses((status = 200, description = "Every device confirmed every parameter", body = BusPatchResult), ErrorResponses))]
async fn patch_bus_config(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(patch): ApiJson<ConfigPatch>,
) -> ApiResult<Json<BusPatchResult>> {
    let bus = state.bus(&p.bus)?;
    let snap = bus.snapshot();
    if let crate::bus::handle::LinkState::Down { reason, .. } = &snap.link {
        return Err(BusError::Down {
            bus: snap.name.clone(),
            reason: reason.clone(),
        }
        .into());
    }
    let online: Vec<_> = snap.devices.values().filter(|d| d.online).collect();
    if online.is_empty() {
        return Err(ApiError::conflict(
            "no-device-online",
            "No device online",
            format!(
                "no device of bus {} is online: nothing to configure",
                snap.name
            ),
        ));
    }
    let mut writes = Vec::new();
    for (param, value) in patch.entries() {
        for dev in &online {
            check_offered(param, dev.dev_id, dev)?;
        }
        writes.push((param, value, to_config(param, value)?));
    }
    let ids: Vec<u8> = online.iter().map(|d| d.dev_id).collect();
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
            for d in &mut devices {
                let why = "not sent: the bus failed an earlier parameter".to_string();
                d.outcomes
                    .not_written
                    .push(NotWritten::new(param, value, raw, why));
            }
            continue;
        }
        let outcome = match bus.write_all(ids.clone(), config).await {
            Ok(o) => o,
            Err(e) => {
                let err = ApiError::from(e);
                for d in &mut devices {
                    let why = err.problem.detail.clone();
                    d.outcomes
                        .not_written
                        .push(NotWritten::new(param, value, raw, why));
                }
                failed = Some(err.with_field(param.key));
                continue;
            }
        };
        methods.push(outcome.one_frame);
        for (id, result) in outcome.per_device {
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
    }
    let result = BusPatchResult {
        bus: snap.name.clone(),
        method: match (methods.is_empty(), methods.iter().all(|m| *m)) {
            (true, _) => "none",
            (false, true) => "one_frame",
            (false, false) => "per_device",
        },
        devices,
        offline: snap
            .devices
            .values()
            .filter(|d| !d.online)
            .map(|d| d.dev_id)
            .collect(),
    };
    match bus_problem(failed, &result) {
        Some(err) => Err(err),
        None => Ok(Json(result)),
    }
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
