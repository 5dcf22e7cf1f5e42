//! Control: enable, disable, target, mode, jog, re-zero for one device, and
//! enable, disable, targets, mode for a group of devices in one call.

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::bus::handle::DeviceState;
use crate::bus::{BusHandle, BusSnapshot, Setpoint, Targets};
use crate::control::targets::{ensure_enabled, setpoint, wait_on_wire, TargetRequest};
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::{
    device_id, known_device, require_revision, AppState, BusPath, DevicePath,
};
use crate::http::telemetry::{firmware_of, TargetView};
use crate::protocol::params::Revision;
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

/// Current mode exists on rev 2.0.8 firmware only.
fn check_mode(mode: CtrlMode, id: u8, dev: &DeviceState) -> ApiResult<()> {
    if mode != CtrlMode::Current {
        return Ok(());
    }
    require_revision("mode", "current mode", Revision::V2_0_8, id, dev)
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

/// The ids of a group request, each known on the bus; `None` = all.
fn group_ids(snap: &BusSnapshot, ids: Option<Vec<i64>>) -> ApiResult<Option<Vec<u8>>> {
    let Some(ids) = ids else { return Ok(None) };
    if ids.is_empty() {
        return Err(ApiError::invalid(
            "ids",
            "ids is empty: omit it to address every device",
        ));
    }
    let mut out = Vec::with_capacity(ids.len());
    for (i, id) in ids.into_iter().enumerate() {
        let id = device_id(&format!("ids[{i}]"), id)?;
        if out.contains(&id) {
            return Err(ApiError::invalid(
                &format!("ids[{i}]"),
                format!("joint {id} appears twice"),
            ));
        }
        known_device(snap, id)?;
        out.push(id);
    }
    Ok(Some(out))
}

fn targets_of(ids: &Option<Vec<u8>>) -> Targets {
    ids.clone().map_or(Targets::All, Targets::Ids)
}

fn done(
    bus: &BusHandle,
    action: &'static str,
    ids: Option<Vec<u8>>,
    value: Option<&'static str>,
) -> Json<ActionDone> {
    Json(ActionDone {
        bus: bus.name().to_owned(),
        action,
        ids,
        value,
    })
}

/// Stores targets for several joints in one write (one coalesced frame where
/// the bus can) and reports whether they reached the wire.
async fn apply_targets(
    state: &AppState,
    bus: &BusHandle,
    snap: &BusSnapshot,
    targets: Vec<(u8, Setpoint)>,
) -> (StatusCode, Json<TargetAck>) {
    let seq = bus.set_targets(&targets);
    let on_wire = wait_on_wire(bus, seq).await;
    let views = targets
        .into_iter()
        .map(|(id, sp)| {
            let dev = snap.devices.get(&id);
            let fw = dev
                .map(firmware_of)
                .unwrap_or(crate::http::telemetry::ASSUMED_FIRMWARE);
            let cal = state.calibration(bus.name(), id);
            JointTarget {
                id,
                target: TargetView::new(sp, fw, &cal, dev.and_then(|d| d.mode)),
            }
        })
        .collect();
    let status = if on_wire {
        StatusCode::OK
    } else {
        StatusCode::ACCEPTED
    };
    (
        status,
        Json(TargetAck {
            bus: bus.name().to_owned(),
            seq,
            on_wire,
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
    let (bus, id) = p.resolve(&state)?;
    known_device(&bus.snapshot(), id)?;
    bus.enable(Targets::Ids(vec![id])).await?;
    Ok(done(bus, "enable", Some(vec![id]), None))
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
    let (bus, id) = p.resolve(&state)?;
    known_device(&bus.snapshot(), id)?;
    bus.disable(Targets::Ids(vec![id])).await?;
    Ok(done(bus, "disable", Some(vec![id]), None))
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
    let (bus, id) = p.resolve(&state)?;
    let snap = bus.snapshot();
    let dev = known_device(&snap, id)?;
    let cal = state.calibration(&snap.name, id);
    let sp = setpoint(dev, &state.limits(&snap.name, id), &cal, &req, "")?;
    ensure_enabled(bus, dev, "a target").await?;
    Ok(apply_targets(&state, bus, &snap, vec![(id, sp)]).await)
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
    let (bus, id) = p.resolve(&state)?;
    let snap = bus.snapshot();
    let mode = CtrlMode::from(req.mode);
    check_mode(mode, id, known_device(&snap, id)?)?;
    bus.set_mode(id, mode).await?;
    Ok(done(bus, "mode", Some(vec![id]), Some(mode.name())))
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
    let (bus, id) = p.resolve(&state)?;
    let snap = bus.snapshot();
    ensure_enabled(bus, known_device(&snap, id)?, "a jog").await?;
    let (dir, name) = match req.direction {
        JogDirection::Cw => (JogDir::Cw, "cw"),
        JogDirection::Ccw => (JogDir::Ccw, "ccw"),
    };
    bus.jog(id, dir).await?;
    Ok(done(bus, "jog", Some(vec![id]), Some(name)))
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
    let (bus, id) = p.resolve(&state)?;
    known_device(&bus.snapshot(), id)?;
    bus.rezero(id).await?;
    Ok(done(bus, "rezero", Some(vec![id]), None))
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
    let bus = state.bus(&p.bus)?;
    let ids = group_ids(&bus.snapshot(), req.ids)?;
    bus.enable(targets_of(&ids)).await?;
    Ok(done(bus, "enable", ids, None))
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
    let bus = state.bus(&p.bus)?;
    let ids = group_ids(&bus.snapshot(), req.ids)?;
    bus.disable(targets_of(&ids)).await?;
    Ok(done(bus, "disable", ids, None))
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
    let bus = state.bus(&p.bus)?;
    if req.targets.is_empty() {
        return Err(ApiError::invalid("targets", "targets is empty"));
    }
    let snap = bus.snapshot();
    let mut out: Vec<(u8, Setpoint)> = Vec::with_capacity(req.targets.len());
    for (i, t) in req.targets.iter().enumerate() {
        let id = device_id(&format!("targets[{i}].id"), t.id)?;
        if out.iter().any(|(seen, _)| *seen == id) {
            return Err(ApiError::invalid(
                &format!("targets[{i}].id"),
                format!("joint {id} appears twice"),
            ));
        }
        let dev = known_device(&snap, id)?;
        let req = TargetRequest {
            position_deg: t.position_deg,
            speed_dps: t.speed_dps,
        };
        out.push((
            id,
            setpoint(
                dev,
                &state.limits(&snap.name, id),
                &state.calibration(&snap.name, id),
                &req,
                &format!("targets[{i}]."),
            )?,
        ));
    }
    for (id, _) in &out {
        if let Some(dev) = snap.devices.get(id) {
            ensure_enabled(bus, dev, "a target").await?;
        }
    }
    Ok(apply_targets(&state, bus, &snap, out).await)
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
    let bus = state.bus(&p.bus)?;
    let snap = bus.snapshot();
    let ids = group_ids(&snap, req.ids)?;
    let mode = CtrlMode::from(req.mode);
    let each: Vec<u8> = ids
        .clone()
        .unwrap_or_else(|| snap.devices.keys().copied().collect());
    // Every device checked before any is switched.
    for &id in &each {
        check_mode(mode, id, known_device(&snap, id)?)?;
    }
    for id in each {
        bus.set_mode(id, mode).await?;
    }
    Ok(done(bus, "mode", ids, Some(mode.name())))
}
