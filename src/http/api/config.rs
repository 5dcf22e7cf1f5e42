//! Configuration: read every parameter (INFO_03..06) in physical units with
//! the raw values beside them, change any subset in one request (each write
//! verified by the bus engine), persist to flash, change a device's id, and
//! serve the parameter table itself. Which parameters exist comes from
//! [`crate::protocol::params`].

use axum::extract::State;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::config_outcome::{NotWritten, PatchOutcomes, Unverified, Written, NOT_SENT};
use super::config_params::{
    api_params, blocks_to_read, check_offered, offered, to_config, Blocks, ConfigPatch, Param,
    ParamValues,
};
use super::config_schema::{ConfigDevice, ConfigView, ParamTable};
use super::openapi::{ErrorResponses, TAG_CONFIG};
use crate::bus::BusError;
use crate::control::Control;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::{known_device, AppState, DevicePath};
use crate::http::telemetry::{hex, revision_of};
use crate::protocol::params::{self, Revision};
use crate::protocol::{BaudLevel, ConfigParam, Info04, InfoBlock};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(read_config, patch_config))
        .routes(routes!(persist))
        .routes(routes!(change_id))
        .routes(routes!(param_table))
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct PatchResult {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    /// In request order; RAM only until persisted.
    pub written: Vec<Written>,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct PersistResult {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    #[schema(example = true)]
    pub persisted: bool,
    #[schema(example = "res")]
    pub verified_by: &'static str,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct IdRequest {
    /// 1..=159, unused on this bus. Stored to flash by the device at once.
    #[schema(minimum = 1, maximum = 159, example = 5)]
    pub new_id: i64,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct IdResult {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub old_id: u8,
    #[schema(example = 5)]
    pub new_id: u8,
    #[schema(example = "res")]
    pub verified_by: &'static str,
}

/// Reads every INFO block a config read needs, in SPEC order.
async fn read_blocks(control: &Control, bus: &str, id: u8) -> ApiResult<Blocks> {
    let mut blocks = Blocks::default();
    for block in blocks_to_read() {
        let reply = control.read_info(bus, id, block).await?;
        if reply.index != block.index() {
            return Err(BusError::UnexpectedReply(format!(
                "device {id} answered a parameter read with another block"
            ))
            .into());
        }
        blocks.0.push((block, reply.data));
    }
    Ok(blocks)
}

/// `info04` for INFO_04: the key the table gives the read, without underscores.
fn block_label(block: InfoBlock) -> String {
    params::by_index(block.index()).map_or_else(
        || format!("info{}", block.index()),
        |r| r.key.replace('_', ""),
    )
}

/// Read every parameter (INFO_03..06) in physical units, raw values beside them.
///
/// Reads INFO_03 to INFO_06 from the device now and shows every parameter of the table in physical
/// units, with its raw value and index, plus the raw INFO bytes.
#[utoipa::path(get, path = "/api/v1/buses/{bus}/devices/{id}/config", tag = TAG_CONFIG, params(DevicePath),
    responses((status = 200, description = "Every parameter, read from the device now", body = ConfigView), ErrorResponses))]
async fn read_config(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<ConfigView>> {
    let (bus, id) = p.resolve(&state)?;
    let revision = revision_of(known_device(&bus.snapshot(), id)?);
    let mut blocks = read_blocks(state.control(), bus.name(), id).await?;
    // The serial number, where the firmware has one (rev 2.0.8).
    let serial = if revision == Some(Revision::V2_0_8) {
        let reply = state
            .control()
            .read_info(bus.name(), id, InfoBlock::Info07)
            .await?;
        blocks.0.push((InfoBlock::Info07, reply.data));
        Some(hex(&reply.data))
    } else {
        None
    };
    let info04 = blocks
        .data(InfoBlock::Info04)
        .map(Info04::from_bytes)
        .unwrap_or_default();
    let raw = blocks.0.iter().map(|(b, d)| (block_label(*b), hex(d)));
    Ok(Json(ConfigView {
        device: ConfigDevice {
            bus: bus.name().to_owned(),
            id,
            revision: revision.map(Revision::as_str),
            baud: BaudLevel::from_raw(info04.baud_level).map(BaudLevel::baud),
            baud_level: info04.baud_level,
            param_ver: info04.param_ver,
            serial_number: serial,
            write_only: write_only_params(revision),
            raw: raw.collect(),
        },
        params: ParamValues::from_blocks(&blocks),
    }))
}

/// Offered parameters no published INFO block shows (rev 2.0.8's): a
/// PATCH writes them, unverifiable; a read cannot show them.
fn write_only_params(revision: Option<Revision>) -> Vec<&'static str> {
    api_params()
        .filter(|p| p.read_back.is_none() && offered(p, revision))
        .map(|p| p.key)
        .collect()
}

/// Change any subset of parameters in one request. Every value is checked
/// before anything is written; each write is confirmed by read-back (the
/// read retried, then the write re-sent, as the bus's retries allow).
///
/// 200 only when every parameter is confirmed. Otherwise a problem whose
/// `partial` (a `PatchOutcomes`) lists every parameter as `written`,
/// `unverified` (sent, confirmation lost: the device may have it; also a
/// write the bus owner did not answer in time) or `not_written`. An
/// unverified parameter does not stop the others; any
/// other failure does (the rest are `not_written`, never sent) and gives
/// the status (e.g. 502 verify-mismatch, 409 device-refused, 503 bus-down).
/// When the only failures are unverified: 504 `write-unverified`. A single
/// write (persist, id) whose confirmation is lost is a 504 `write-unverified` too.
#[utoipa::path(patch, path = "/api/v1/buses/{bus}/devices/{id}/config", tag = TAG_CONFIG, params(DevicePath),
    request_body(content = ConfigPatch, example = json!({"pos_kp": 1.25, "max_current_a": 2.0, "burst_plus_ms": 100.0})),
    responses((status = 200, description = "Every parameter written and confirmed", body = PatchResult), ErrorResponses))]
async fn patch_config(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(patch): ApiJson<ConfigPatch>,
) -> ApiResult<Json<PatchResult>> {
    let (bus, id) = p.resolve(&state)?;
    let snap = bus.snapshot();
    let dev = known_device(&snap, id)?;
    let mut writes = Vec::new();
    for (param, value) in patch.entries() {
        check_offered(param, id, dev)?;
        writes.push((param, value, to_config(param, value)?));
    }
    let (out, failed) = write_in_turn(state.control(), bus.name(), id, writes).await?;
    match patch_problem(failed, &out) {
        Some(err) => Err(err),
        None => Ok(Json(PatchResult {
            bus: bus.name().to_owned(),
            id,
            written: out.written,
        })),
    }
}

/// Writes each parameter in turn; an unverified one does not stop the
/// rest, any other failure does (the rest are never sent).
async fn write_in_turn(
    control: &Control,
    bus: &str,
    id: u8,
    writes: Vec<(Param, f64, ConfigParam)>,
) -> ApiResult<(PatchOutcomes, Option<ApiError>)> {
    let mut out = PatchOutcomes::default();
    let mut failed: Option<ApiError> = None;
    for (param, value, config) in writes {
        let raw = config.index_value().1;
        if failed.is_some() {
            out.not_written
                .push(NotWritten::new(param, value, raw, NOT_SENT.into()));
            continue;
        }
        match control.write_config(bus, id, config).await? {
            Ok(outcome) => out.written.push(Written::new(param, value, &outcome)),
            Err(BusError::Unverified { reason, .. }) => {
                out.unverified
                    .push(Unverified::new(param, value, raw, reason));
            }
            // The owner may still send it: unknown, and the rest waits no longer.
            Err(e @ BusError::OwnerTimeout) => {
                out.unverified
                    .push(Unverified::new(param, value, raw, e.to_string()));
                failed = Some(ApiError::from(e).with_field(param.key));
            }
            Err(e) => {
                let err = ApiError::from(e);
                let reason = err.problem.detail.clone();
                out.not_written
                    .push(NotWritten::new(param, value, raw, reason));
                failed = Some(err.with_field(param.key));
            }
        }
    }
    Ok((out, failed))
}

/// The problem a PATCH answers unless everything was confirmed: the
/// failure that stopped it, else "unverified"; `partial` lists all three.
fn patch_problem(failed: Option<ApiError>, out: &PatchOutcomes) -> Option<ApiError> {
    let unverified: Vec<&str> = out.unverified.iter().map(|u| u.param).collect();
    let unverified = unverified.join(", ");
    let mut err = match (failed, out.unverified.first()) {
        (None, None) => return None,
        (Some(mut err), _) => {
            let field = err.problem.field.clone().unwrap_or_default();
            err.problem.detail = format!("{field}: {}", err.problem.detail);
            err
        }
        (None, Some(first)) => ApiError::writes_unverified(format!(
            "sent, not confirmed (the device may or may not have them): {unverified}"
        ))
        .with_field(first.param),
    };
    if !err.problem.kind.ends_with("write-unverified") && !unverified.is_empty() {
        err.problem.detail = format!("{}; unconfirmed: {unverified}", err.problem.detail);
    }
    Some(err.with_partial(serde_json::to_value(out).unwrap_or_default()))
}

/// Persist the RAM parameters to flash (WRITE_FLASH, key 0xA5), confirmed by RES.
///
/// WRITE_FLASH with key 0xA5: the device stores its RAM parameters (gains, limits, baud level) so
/// they survive a power cycle. Confirmed by the device's RES reply.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/devices/{id}/config/persist", tag = TAG_CONFIG, params(DevicePath),
    responses((status = 200, description = "Parameters stored in flash", body = PersistResult), ErrorResponses))]
async fn persist(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<PersistResult>> {
    let (bus, id) = p.resolve(&state)?;
    let outcome = state.control().persist(bus.name(), id).await?;
    Ok(Json(PersistResult {
        bus: bus.name().to_owned(),
        id,
        persisted: true,
        verified_by: outcome.verified_by,
    }))
}

/// Change a device's id (stored to flash at once; the device answers from the new id).
///
/// CONFIG_SET_ID: the device stores the new id in flash at once and answers from it. 409 when the
/// new id is taken on this bus. The registry follows the device to its new id.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/devices/{id}/id", tag = TAG_CONFIG, params(DevicePath),
    request_body(content = IdRequest, example = json!({"new_id": 5})),
    responses((status = 200, description = "Id changed, confirmed from the new id", body = IdResult), ErrorResponses))]
async fn change_id(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(req): ApiJson<IdRequest>,
) -> ApiResult<Json<IdResult>> {
    let (bus, id) = p.resolve(&state)?;
    let (new_id, outcome) = state
        .control()
        .change_id(bus.name(), id, req.new_id)
        .await?;
    Ok(Json(IdResult {
        bus: bus.name().to_owned(),
        old_id: id,
        new_id,
        verified_by: outcome.verified_by,
    }))
}

/// The parameter table: every config index of SPEC §4.3 with its raw type,
/// scale, range, reply, read-back field, storage and revision. The dashboard
/// builds its configuration form from it.
///
/// The dashboard builds its configuration form from this table; clients can use it to validate
/// values before a PATCH.
#[utoipa::path(get, path = "/api/v1/params", tag = TAG_CONFIG,
    responses((status = 200, description = "The parameter table, one row per index", body = ParamTable), ErrorResponses))]
async fn param_table() -> Json<ParamTable> {
    Json(ParamTable::new())
}
