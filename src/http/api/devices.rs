//! Devices on a bus: the list with latest telemetry in physical units and
//! its age, and one device's full state (INFO_01 and INFO_02 decoded).

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_DEVICES};
use crate::bus::handle::DeviceState;
use crate::bus::BusError;
use crate::control::books::streams::Driver;
use crate::control::calibration::CalibrationView;
use crate::control::limits::JointLimits;
use crate::control::Control;
use crate::hands::Calibration;
use crate::http::error::ApiResult;
use crate::http::extract::{ApiPath, ApiQuery};
use crate::http::state::{known_device, AppState, BusPath, DevicePath};
use crate::http::telemetry::{
    disabled_reason, firmware_of, motion_view, reset_view, revision_of, status_view, FaultView,
    MotionView, ResetView, RevisionView, StatusView, TargetView,
};
use crate::protocol::{CtrlMode, InfoBlock, ReplyBody};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_devices))
        .routes(routes!(get_device))
}

/// One row of the device list.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DeviceSummary {
    #[schema(example = 1)]
    pub id: u8,
    /// The joint's name from the config file (`[[joint]]`), if any.
    #[schema(example = "index_mcp")]
    pub name: Option<String>,
    #[schema(example = true)]
    pub online: bool,
    /// Protocol revision, `2.0.1` or `2.0.8` (absent until known: see the device's `protocol`).
    #[schema(example = "2.0.8")]
    pub revision: Option<&'static str>,
    /// fsm state name from the latest INFO_01.
    #[schema(example = "run")]
    pub state: Option<&'static str>,
    pub fault: Option<FaultView>,
    /// Control mode the daemon last set (`position` at power-up).
    #[schema(example = "position")]
    pub mode: Option<&'static str>,
    #[schema(example = 45.5)]
    pub angle_deg: Option<f64>,
    /// Output-shaft speed, °/s.
    #[schema(example = 21.1)]
    pub speed_dps: Option<f64>,
    #[schema(example = 0.25)]
    pub q_current_a: Option<f64>,
    #[schema(example = 31.0)]
    pub temp_c: Option<f64>,
    #[schema(example = 12.1)]
    pub vbus_v: Option<f64>,
    /// Age of the freshest telemetry block, milliseconds.
    #[schema(example = 8.2)]
    pub telemetry_age_ms: Option<f64>,
    pub target: Option<TargetView>,
    /// False while the device may hold a target the daemon does not know
    /// (not heard from yet, or found enabled at start with the bus's
    /// `on_start = "keep"` and sent nothing since): `target` is then `null`
    /// meaning *unknown*, not "no target". True otherwise: `target` is the
    /// target last put on the wire, or `null` when the joint holds none of
    /// the daemon's (disabled, or enabled and holding where it stood).
    #[schema(example = true)]
    pub target_known: bool,
    /// Why the joint is disabled, when the daemon knows: `reset` (the
    /// device lost power or rebooted), `fault`, `estop`, `request` (a
    /// disable: REST, WebSocket, the teleop watchdog), `on_start` (found
    /// enabled at start, disabled by the bus's `on_start`), `shutdown`.
    /// `null` while enabled, or if nothing disabled it since the daemon started.
    #[schema(example = "reset")]
    pub disabled_reason: Option<&'static str>,
    /// Resets (power cuts, reboots) detected since the daemon started.
    #[schema(example = 0)]
    pub resets: u64,
    /// The latest detected reset.
    pub last_reset: Option<ResetView>,
    #[schema(example = 450.0)]
    pub control_hz: f64,
    #[schema(example = 45.0)]
    pub telemetry_hz: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DeviceList {
    #[schema(example = "sim0")]
    pub bus: String,
    pub devices: Vec<DeviceSummary>,
}

/// One device's full state.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DeviceDetail {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    /// The joint's name from the config file (`[[joint]]`), if any.
    #[schema(example = "index_mcp")]
    pub name: Option<String>,
    #[schema(example = true)]
    pub online: bool,
    /// The firmware version from INFO_01 (`soft_ver`).
    #[schema(example = "1.2.8")]
    pub firmware: Option<String>,
    /// The protocol revision it speaks (absent until the config or the device told).
    pub protocol: Option<RevisionView>,
    #[schema(example = "position")]
    pub mode: Option<&'static str>,
    /// INFO_01 decoded (absent until the device has answered one).
    pub status: Option<StatusView>,
    /// INFO_02 decoded.
    pub motion: Option<MotionView>,
    /// The target last put on the wire.
    pub target: Option<TargetView>,
    /// False while the device may hold a target the daemon does not know
    /// (not heard from yet, or found enabled at start with the bus's
    /// `on_start = "keep"` and sent nothing since): `target` is then `null`
    /// meaning *unknown*, not "no target". True otherwise: `target` is the
    /// target last put on the wire, or `null` when the joint holds none of
    /// the daemon's (disabled, or enabled and holding where it stood).
    #[schema(example = true)]
    pub target_known: bool,
    /// Why the joint is disabled, when the daemon knows: `reset` (the
    /// device lost power or rebooted), `fault`, `estop`, `request` (a
    /// disable: REST, WebSocket, the teleop watchdog), `on_start` (found
    /// enabled at start, disabled by the bus's `on_start`), `shutdown`.
    /// `null` while enabled, or if nothing disabled it since the daemon started.
    #[schema(example = "reset")]
    pub disabled_reason: Option<&'static str>,
    /// Resets (power cuts, reboots) detected since the daemon started.
    #[schema(example = 0)]
    pub resets: u64,
    /// The latest detected reset.
    pub last_reset: Option<ResetView>,
    /// Soft limits that apply to targets of this joint, in its calibrated
    /// frame (the config gives them in device degrees).
    pub limits: JointLimits,
    /// The current limit a grasp or homing lowered and could not write back
    /// yet, A: jointd writes it and reads it back as soon as the joint
    /// answers, and refuses every new motion of the joint (409
    /// `current-limit-owed`) until then. `null`: nothing owed.
    #[schema(example = json!(null))]
    pub current_limit_owed_a: Option<f64>,
    /// The program streaming setpoints to this joint now (a WebSocket
    /// client, ROS 2 joint commands), if one is. `null`: none.
    #[schema(example = json!(null))]
    pub streamed_by: Option<Driver>,
    /// Its calibration, when it has one: every angle, speed and q current
    /// here is in the joint's frame; the `raw` fields stay the device's.
    pub calibration: Option<CalibrationView>,
    #[schema(example = 0)]
    pub missed_polls: u32,
    #[schema(example = 450.0)]
    pub control_hz: f64,
    #[schema(example = 45.0)]
    pub telemetry_hz: f64,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct FreshQuery {
    /// Read INFO_01 and INFO_02 from the device now instead of answering
    /// from the latest poll (504 if it does not answer).
    #[serde(default)]
    #[param(example = false)]
    pub fresh: bool,
}

fn summary(
    dev: &DeviceState,
    name: Option<&str>,
    cal: &Calibration,
    now: Instant,
) -> DeviceSummary {
    let fw = firmware_of(dev);
    let status = dev
        .info01
        .as_ref()
        .map(|(i, at)| status_view(i, revision_of(dev), cal, *at, now));
    let motion = dev
        .info02
        .as_ref()
        .map(|(i, at)| motion_view(i, fw, cal, *at, now));
    let age = [
        status.as_ref().map(|s| s.age_ms),
        motion.as_ref().map(|m| m.age_ms),
    ]
    .into_iter()
    .flatten()
    .reduce(f64::min);
    DeviceSummary {
        id: dev.dev_id,
        name: name.map(str::to_owned),
        online: dev.online,
        revision: revision_of(dev).map(crate::protocol::params::Revision::as_str),
        state: status.as_ref().map(|s| s.state),
        fault: status.as_ref().map(|s| s.fault.clone()),
        mode: dev.mode.map(CtrlMode::name),
        angle_deg: motion
            .as_ref()
            .map(|m| m.angle_deg)
            .or(status.as_ref().map(|s| s.angle_deg)),
        speed_dps: motion.as_ref().map(|m| m.speed_dps),
        q_current_a: motion.as_ref().map(|m| m.q_current_a),
        temp_c: status.as_ref().map(|s| s.temp_c),
        vbus_v: status.as_ref().map(|s| s.vbus_v),
        telemetry_age_ms: age,
        target: dev
            .target_sent
            .map(|sp| TargetView::new(sp, fw, cal, dev.mode)),
        target_known: dev.target_known,
        disabled_reason: disabled_reason(dev),
        resets: dev.resets,
        last_reset: reset_view(dev, now),
        control_hz: dev.control_hz,
        telemetry_hz: dev.telemetry_hz,
    }
}

/// List the devices of a bus with their latest telemetry.
///
/// Every device the bus has seen (by discovery, a scan or its power-up announcement), online or
/// not, with its latest state, fault, angle, speed, current, temperature and bus voltage, and how
/// old that telemetry is.
#[utoipa::path(get, path = "/api/v1/buses/{bus}/devices", tag = TAG_DEVICES,
    params(BusPath),
    responses((status = 200, description = "Devices known on the bus", body = DeviceList), ErrorResponses))]
async fn list_devices(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
) -> ApiResult<Json<DeviceList>> {
    let snap = state.control().reader(&p.bus)?.snapshot();
    let now = Instant::now();
    Ok(Json(DeviceList {
        bus: snap.name.clone(),
        devices: snap
            .devices
            .values()
            .map(|d| {
                let cal = state.control().calibration(&snap.name, d.dev_id);
                summary(
                    d,
                    state.control().joint_name(&snap.name, d.dev_id),
                    &cal,
                    now,
                )
            })
            .collect(),
    }))
}

/// One device's full state: INFO_01 and INFO_02 decoded, firmware, fault names.
///
/// INFO_01 and INFO_02 decoded with their raw bytes, firmware version, fault names (active and
/// latched), the current target and why a joint was disabled, if it was. `fresh=true` polls the
/// device now instead of answering from the latest telemetry.
#[utoipa::path(get, path = "/api/v1/buses/{bus}/devices/{id}", tag = TAG_DEVICES,
    params(DevicePath, FreshQuery),
    responses((status = 200, description = "The device's state", body = DeviceDetail), ErrorResponses))]
async fn get_device(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiQuery(q): ApiQuery<FreshQuery>,
) -> ApiResult<Json<DeviceDetail>> {
    let (bus, id) = p.resolve(&state)?;
    let snap = bus.snapshot();
    let mut dev = known_device(&snap, id)?.clone();
    if q.fresh {
        refresh(state.control(), bus.name(), &mut dev).await?;
    }
    let now = Instant::now();
    let fw = firmware_of(&dev);
    let cal = state.control().calibration(&snap.name, id);
    Ok(Json(DeviceDetail {
        bus: snap.name.clone(),
        id,
        name: state
            .control()
            .joint_name(&snap.name, id)
            .map(str::to_owned),
        online: dev.online,
        firmware: dev.info01.as_ref().map(|(i, _)| i.firmware().dotted()),
        mode: dev.mode.map(CtrlMode::name),
        status: dev
            .info01
            .as_ref()
            .map(|(i, at)| status_view(i, revision_of(&dev), &cal, *at, now)),
        protocol: dev.firmware.as_ref().map(RevisionView::new),
        motion: dev
            .info02
            .as_ref()
            .map(|(i, at)| motion_view(i, fw, &cal, *at, now)),
        target: dev
            .target_sent
            .map(|sp| TargetView::new(sp, fw, &cal, dev.mode)),
        target_known: dev.target_known,
        disabled_reason: disabled_reason(&dev),
        resets: dev.resets,
        last_reset: reset_view(&dev, now),
        limits: limits_in_joint_frame(state.control().limits(&snap.name, id), &cal),
        current_limit_owed_a: bus
            .owed_limits()
            .get(id)
            .map(crate::protocol::units::current_limit_a),
        streamed_by: state
            .control()
            .stream_book()
            .driver_of(&crate::control::JointRef {
                bus: snap.name.clone(),
                id,
            }),
        calibration: (!cal.is_identity()).then(|| CalibrationView::new(&snap.name, id, &cal)),
        missed_polls: dev.missed_polls,
        control_hz: dev.control_hz,
        telemetry_hz: dev.telemetry_hz,
    }))
}

/// Reads INFO_01 then INFO_02 from the device into `dev`.
async fn refresh(control: &Control, bus: &str, dev: &mut DeviceState) -> ApiResult<()> {
    let id = dev.dev_id;
    let r1 = control.read_info(bus, id, InfoBlock::Info01).await?;
    let r2 = control.read_info(bus, id, InfoBlock::Info02).await?;
    let now = Instant::now();
    match (r1.body(), r2.body()) {
        (ReplyBody::Info01(a), ReplyBody::Info02(b)) => {
            dev.info01 = Some((a, now));
            dev.info02 = Some((b, now));
            dev.online = true;
            Ok(())
        }
        _ => Err(BusError::UnexpectedReply(format!(
            "device {id} answered a read with another block"
        ))
        .into()),
    }
}

/// Soft limits (device degrees, as configured) in the joint's calibrated frame.
fn limits_in_joint_frame(limits: JointLimits, cal: &Calibration) -> JointLimits {
    let (min_deg, max_deg) = cal.range_to_joint((limits.min_deg, limits.max_deg));
    JointLimits {
        min_deg,
        max_deg,
        ..limits
    }
}
