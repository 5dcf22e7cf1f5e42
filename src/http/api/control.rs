//! Control: enable, disable, target, mode, jog, re-zero for one device, and
//! enable, disable, targets, mode for a group of devices in one call.

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::actions::TargetsSet;
use crate::control::targets::TargetRequest;
use crate::http::error::ApiResult;
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::{AppState, BusPath, DevicePath};
use crate::http::telemetry::{firmware_of, TargetView};
use crate::protocol::{CtrlMode, JogDir};

/// What a target request did.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct TargetAck {
    #[schema(example = "sim0")]
    pub bus: String,
    /// Sequence number of this write in the bus's setpoint store.
    #[schema(example = 42)]
    pub seq: u64,
    /// True when the frame carrying the targets has been written to the
    /// port (status 200); false when still waiting (status 202).
    #[schema(example = true)]
    pub on_wire: bool,
    pub targets: Vec<JointTarget>,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct JointTarget {
    #[schema(example = 1)]
    pub id: u8,
    #[serde(flatten)]
    pub target: TargetView,
}

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(enable_one))
        .routes(routes!(disable_one))
        .routes(routes!(target_one))
        .routes(routes!(mode_one))
        .routes(routes!(jog))
        .routes(routes!(rezero))
        .routes(routes!(enable_group))
        .routes(routes!(disable_group))
        .routes(routes!(target_group))
        .routes(routes!(mode_group))
}

/// What a control action did.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ActionDone {
    #[schema(example = "sim0")]
    pub bus: String,
    /// `enable`, `disable`, `mode`, `jog`, `rezero`.
    #[schema(example = "enable")]
    pub action: &'static str,
    /// Devices addressed; absent = every device on the bus.
    #[schema(example = json!([1]))]
    pub ids: Option<Vec<u8>>,
    /// Detail of the action, e.g. the mode set or the jog direction.
    #[schema(example = "position")]
    pub value: Option<&'static str>,
}

/// Devices of a group action; no `ids` = every device on the bus.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GroupRequest {
    #[schema(example = json!([1, 2, 3]), min_items = 1)]
    pub ids: Option<Vec<i64>>,
}

#[derive(Debug, Clone, Copy, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ModeName {
    Position,
    Speed,
    /// Rev 2.0.8 firmware only (422 for V2.0.1 devices). The joint then
    /// follows a q-axis current, not a position or speed: targets are
    /// refused until it is back in position or speed mode.
    Current,
}

impl From<ModeName> for CtrlMode {
    fn from(m: ModeName) -> Self {
        match m {
            ModeName::Position => CtrlMode::Position,
            ModeName::Speed => CtrlMode::Speed,
            ModeName::Current => CtrlMode::Current,
        }
    }
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct ModeRequest {
    pub mode: ModeName,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GroupModeRequest {
    #[schema(example = json!([1, 2]))]
    pub ids: Option<Vec<i64>>,
    pub mode: ModeName,
}

/// `cw` = +5°, `ccw` = −3°; the device re-zeroes afterwards (SPEC §4.2).
#[derive(Debug, Clone, Copy, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum JogDirection {
    Cw,
    Ccw,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct JogRequest {
    pub direction: JogDirection,
}

/// One joint of a group target.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GroupTarget {
    #[schema(example = 1, minimum = 1, maximum = 159)]
    pub id: i64,
    /// Output angle, degrees (see `TargetRequest`).
    #[schema(example = 45.0, minimum = -255.0, maximum = 255.0)]
    pub position_deg: Option<f64>,
    /// Output-shaft °/s (see `TargetRequest`).
    #[schema(example = 30.0, minimum = -527.0, maximum = 527.0)]
    pub speed_dps: Option<f64>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GroupTargetRequest {
    pub targets: Vec<GroupTarget>,
}

fn done(
    bus: &str,
    action: &'static str,
    ids: Option<Vec<u8>>,
    value: Option<&'static str>,
) -> Json<ActionDone> {
    Json(ActionDone {
        bus: bus.to_owned(),
        action,
        ids,
        value,
    })
}

/// The answer to targets stored: 200 once on the wire, 202 while stored
/// for the next control frame; each target as the joint reads it.
fn target_ack(state: &AppState, bus: &str, set: TargetsSet) -> (StatusCode, Json<TargetAck>) {
    let views = set
        .setpoints
        .into_iter()
        .map(|(id, sp)| {
            let dev = set.snapshot.devices.get(&id);
            let fw = dev
                .map(firmware_of)
                .unwrap_or(crate::http::telemetry::ASSUMED_FIRMWARE);
            let cal = state.control().calibration(bus, id);
            JointTarget {
                id,
                target: TargetView::new(sp, fw, &cal, dev.and_then(|d| d.mode)),
            }
        })
        .collect();
    let status = if set.on_wire {
        StatusCode::OK
    } else {
        StatusCode::ACCEPTED
    };
    (
        status,
        Json(TargetAck {
            bus: bus.to_owned(),
            seq: set.seq,
            on_wire: set.on_wire,
            targets: views,
        }),
    )
}

/// Enable one device (power up and hold; the first enable aligns for ~1 s).
///
/// Sends CMD_ENABLE to one device and waits until its status says it is enabled; the joint then
/// holds its current angle. The first enable after power-up aligns the encoder (state `align`,
/// about 1 s) before `run`.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/devices/{id}/enable", tag = TAG_CONTROL, params(DevicePath),
    responses((status = 200, description = "Enable sent and confirmed by the bus", body = ActionDone), ErrorResponses))]
async fn enable_one(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<ActionDone>> {
    let id = state.control().joint_id(&p.bus, p.id)?;
    state.control().enable(&p.bus, Some(vec![id])).await?;
    Ok(done(&p.bus, "enable", Some(vec![id]), None))
}

/// Disable one device (release the motor).
///
/// Sends CMD_DISABLE: the motor is released and the joint goes limp. Any target, setpoint stream or
/// move on this joint stops with it.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/devices/{id}/disable", tag = TAG_CONTROL, params(DevicePath),
    responses((status = 200, description = "Disable sent", body = ActionDone), ErrorResponses))]
async fn disable_one(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<ActionDone>> {
    let id = state.control().joint_id(&p.bus, p.id)?;
    state.control().disable(&p.bus, Some(vec![id])).await?;
    Ok(done(&p.bus, "disable", Some(vec![id]), None))
}

/// Set one joint's target (position in degrees with a speed limit in °/s,
/// or a speed in speed mode). Outside the soft limits: 422, never clamped.
///
/// Position mode: `position_deg` with an optional `speed_dps` limit (output-shaft °/s; 30 when left
/// out). Speed mode: `speed_dps` only. Values outside the configured soft limits are refused with
/// 422 and never clamped. 409 while the joint is not enabled, or while it aligns its encoder after
/// its first enable (state `align`, about a second): send the target once its state is `run`. 200
/// when the reference went out on the wire, 202 when it is stored for the next control frame.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/devices/{id}/target", tag = TAG_CONTROL, params(DevicePath),
    request_body(content = TargetRequest, example = json!({"position_deg": 45.0, "speed_dps": 30.0})),
    responses((status = 200, description = "Target written to the wire", body = TargetAck),
        (status = 202, description = "Target stored; not yet on the wire", body = TargetAck), ErrorResponses))]
async fn target_one(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(req): ApiJson<TargetRequest>,
) -> ApiResult<(StatusCode, Json<TargetAck>)> {
    let set = state
        .control()
        .set_targets(&p.bus, &[(p.id, req, String::new())])
        .await?;
    Ok(target_ack(&state, &p.bus, set))
}

/// Switch one device between position and speed mode (not saved by the device).
///
/// Writes CTRL_MODE_SW and reads the mode back. The device does not save the mode: after a power
/// cycle it is in position mode again.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/devices/{id}/mode", tag = TAG_CONTROL, params(DevicePath),
    request_body(content = ModeRequest, example = json!({"mode": "speed"})),
    responses((status = 200, description = "Mode set and verified", body = ActionDone), ErrorResponses))]
async fn mode_one(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(req): ApiJson<ModeRequest>,
) -> ApiResult<Json<ActionDone>> {
    let id = state.control().joint_id(&p.bus, p.id)?;
    let mode = CtrlMode::from(req.mode);
    state
        .control()
        .set_mode(&p.bus, Some(vec![id]), mode)
        .await?;
    Ok(done(&p.bus, "mode", Some(vec![id]), Some(mode.name())))
}

/// Jog an enabled device: `cw` +5°, `ccw` −3°; it re-zeroes afterwards. 409 while disabled.
///
/// Nudges an enabled joint: `cw` moves +5°, `ccw` −3°. The device resets its zero to the new
/// position afterwards (the angle reads about 0), as the protocol defines a jog.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/devices/{id}/jog", tag = TAG_CONTROL, params(DevicePath),
    request_body(content = JogRequest, example = json!({"direction": "cw"})),
    responses((status = 200, description = "Jog sent", body = ActionDone), ErrorResponses))]
async fn jog(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(req): ApiJson<JogRequest>,
) -> ApiResult<Json<ActionDone>> {
    let id = state.control().joint_id(&p.bus, p.id)?;
    let (dir, name) = match req.direction {
        JogDirection::Cw => (JogDir::Cw, "cw"),
        JogDirection::Ccw => (JogDir::Ccw, "ccw"),
    };
    state.control().jog(&p.bus, id, dir).await?;
    Ok(done(&p.bus, "jog", Some(vec![id]), Some(name)))
}

/// Make the current output position the new 0°.
///
/// UPDATE_FIN_ZERO: the output angle reads 0° at the current position from now on. The device keeps
/// the new zero; targets and soft limits are relative to it.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/devices/{id}/rezero", tag = TAG_CONTROL, params(DevicePath),
    responses((status = 200, description = "Zero set", body = ActionDone), ErrorResponses))]
async fn rezero(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<ActionDone>> {
    let id = state.control().joint_id(&p.bus, p.id)?;
    state.control().rezero(&p.bus, id).await?;
    Ok(done(&p.bus, "rezero", Some(vec![id]), None))
}

/// Enable a group of devices (no `ids`: every device on the bus).
///
/// Enables every listed device (every device on the bus when `ids` is left out) with per-device
/// control frames, then waits for each to report enabled.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/control/enable", tag = TAG_CONTROL, params(BusPath),
    request_body(content = GroupRequest, example = json!({"ids": [1, 2, 3]})),
    responses((status = 200, description = "Enable sent", body = ActionDone), ErrorResponses))]
async fn enable_group(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<GroupRequest>,
) -> ApiResult<Json<ActionDone>> {
    let ids = state.control().group_ids(&p.bus, req.ids)?;
    state.control().enable(&p.bus, ids.clone()).await?;
    Ok(done(&p.bus, "enable", ids, None))
}

/// Disable a group of devices (no `ids`: every device on the bus).
///
/// Disables every listed device (every device on the bus when `ids` is left out): the motors are
/// released.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/control/disable", tag = TAG_CONTROL, params(BusPath),
    request_body(content = GroupRequest, example = json!({"ids": [1, 2, 3]})),
    responses((status = 200, description = "Disable sent", body = ActionDone), ErrorResponses))]
async fn disable_group(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<GroupRequest>,
) -> ApiResult<Json<ActionDone>> {
    let ids = state.control().group_ids(&p.bus, req.ids)?;
    state.control().disable(&p.bus, ids.clone()).await?;
    Ok(done(&p.bus, "disable", ids, None))
}

/// Set several joints' targets in one call: all are checked first (one bad
/// target rejects the whole request), then stored in one write.
///
/// Every target is checked against the soft limits and the devices' states before anything is
/// stored: one bad target refuses the whole request (422 or 409; 409 also while a joint aligns
/// after its first enable). The accepted targets go out together in the next control cycle.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/control/targets", tag = TAG_CONTROL, params(BusPath),
    request_body(content = GroupTargetRequest, example = json!({"targets": [
        {"id": 1, "position_deg": 30.0, "speed_dps": 30.0},
        {"id": 2, "position_deg": -15.5}]})),
    responses((status = 200, description = "Targets written to the wire", body = TargetAck),
        (status = 202, description = "Targets stored; not yet on the wire", body = TargetAck), ErrorResponses))]
async fn target_group(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<GroupTargetRequest>,
) -> ApiResult<(StatusCode, Json<TargetAck>)> {
    let targets: Vec<(i64, TargetRequest, String)> = req
        .targets
        .into_iter()
        .enumerate()
        .map(|(i, t)| {
            let target = TargetRequest {
                position_deg: t.position_deg,
                speed_dps: t.speed_dps,
            };
            (t.id, target, format!("targets[{i}]."))
        })
        .collect();
    let set = state.control().set_targets(&p.bus, &targets).await?;
    Ok(target_ack(&state, &p.bus, set))
}

/// Switch a group of devices between position and speed mode.
///
/// Writes CTRL_MODE_SW to each listed device and reads each mode back; the answer lists the devices
/// switched.
#[utoipa::path(put, path = "/api/v1/buses/{bus}/control/mode", tag = TAG_CONTROL, params(BusPath),
    request_body(content = GroupModeRequest, example = json!({"ids": [1, 2], "mode": "position"})),
    responses((status = 200, description = "Mode set on every device", body = ActionDone), ErrorResponses))]
async fn mode_group(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
    ApiJson(req): ApiJson<GroupModeRequest>,
) -> ApiResult<Json<ActionDone>> {
    let ids = state.control().group_ids(&p.bus, req.ids)?;
    let mode = CtrlMode::from(req.mode);
    state.control().set_mode(&p.bus, ids.clone(), mode).await?;
    Ok(done(&p.bus, "mode", ids, Some(mode.name())))
}
