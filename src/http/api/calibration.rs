//! Joint calibrations: offset, direction and usable range, read, set and
//! cleared per joint (by bus and id), listed per hand; saved in the state
//! file. Every angle the API takes or reports is in the calibrated frame
//! ([`crate::hands::calibration`]); the device's own zero is not touched.

use axum::extract::State;
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_CONTROL};
use crate::control::calibration::{self, CalibrationRequest, CalibrationView};
use crate::hands::Calibration;
use crate::http::error::{ApiError, ApiResult};
use crate::http::extract::{ApiJson, ApiPath};
use crate::http::state::{known_device, AppState, DevicePath};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(
            get_calibration,
            put_calibration,
            delete_calibration
        ))
        .routes(routes!(hand_calibration))
}

/// A joint's calibration.
///
/// Its offset, direction and usable range as saved in the state file; the
/// identity (offset 0, no flip, no range) when none was set.
#[utoipa::path(get, path = "/api/v1/buses/{bus}/devices/{id}/calibration", tag = TAG_CONTROL,
    params(DevicePath),
    responses((status = 200, description = "The calibration", body = CalibrationView), ErrorResponses))]
async fn get_calibration(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<CalibrationView>> {
    let (bus, id) = p.resolve(&state)?;
    let cal = state.control().calibration(bus.name(), id);
    Ok(Json(CalibrationView::new(bus.name(), id, &cal)))
}

/// Set a joint's calibration (replacing it whole), in the state file.
///
/// From now on every angle of this joint the API takes or reports is
/// `sign · (device angle − offset_deg)` (sign −1 with `flip`; speeds and
/// the q current turn with it), and a target outside `range_deg` is refused
/// (422). Soft limits keep applying to the device angle. The device's own
/// zero is not touched (that is `rezero`). Saved before the answer: it
/// survives a restart. Only for a device on the bus (404 otherwise: an id
/// mistyped would calibrate a joint that is not there).
#[utoipa::path(put, path = "/api/v1/buses/{bus}/devices/{id}/calibration", tag = TAG_CONTROL,
    params(DevicePath),
    request_body(content = CalibrationRequest, example = json!({"offset_deg": -42.5, "flip": false, "range_deg": [0.0, 90.0]})),
    responses((status = 200, description = "Calibration saved", body = CalibrationView), ErrorResponses))]
async fn put_calibration(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
    ApiJson(req): ApiJson<CalibrationRequest>,
) -> ApiResult<Json<CalibrationView>> {
    let (bus, id) = p.resolve(&state)?;
    known_device(&bus.snapshot(), id)?;
    let cal = req.checked()?;
    calibration::save(state.control(), bus.name(), id, cal)?;
    Ok(Json(CalibrationView::new(bus.name(), id, &cal)))
}

/// Clear a joint's calibration: its angles read as the device's again.
///
/// Removed from the state file before the answer, which gives the
/// calibration as it was. Also for a device no longer on the bus, so a
/// calibration left behind can be cleared.
#[utoipa::path(delete, path = "/api/v1/buses/{bus}/devices/{id}/calibration", tag = TAG_CONTROL,
    params(DevicePath),
    responses((status = 200, description = "Calibration cleared; as it was", body = CalibrationView), ErrorResponses))]
async fn delete_calibration(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<DevicePath>,
) -> ApiResult<Json<CalibrationView>> {
    let (bus, id) = p.resolve(&state)?;
    let was = state.control().calibration(bus.name(), id);
    calibration::save(state.control(), bus.name(), id, Calibration::IDENTITY)?;
    Ok(Json(CalibrationView::new(bus.name(), id, &was)))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub(crate) struct HandPath {
    /// The hand's name, as configured.
    #[param(example = "left")]
    pub hand: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct HandCalibration {
    #[schema(example = "left")]
    pub hand: String,
    pub joints: Vec<JointCalibration>,
}

#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct JointCalibration {
    /// The joint's name in the hand.
    #[schema(example = "index_mcp")]
    pub joint: String,
    pub calibration: CalibrationView,
}

/// The calibrations of a hand's joints, by joint name.
///
/// One entry per joint of the hand (`[[hand]]` in the config), in its order,
/// with the identity for a joint that has none.
#[utoipa::path(get, path = "/api/v1/hands/{hand}/calibration", tag = TAG_CONTROL,
    params(HandPath),
    responses((status = 200, description = "The hand's calibrations", body = HandCalibration), ErrorResponses))]
async fn hand_calibration(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<HandPath>,
) -> ApiResult<Json<HandCalibration>> {
    let hand = state
        .control()
        .hands()
        .and_then(|store| store.hand(&p.hand))
        .ok_or_else(|| {
            ApiError::not_found("unknown-hand", format!("no hand named `{}`", p.hand))
        })?;
    let joints = hand
        .joints
        .iter()
        .map(|j| JointCalibration {
            joint: j.name.clone(),
            calibration: CalibrationView::new(
                &j.bus,
                j.id,
                &state.control().calibration(&j.bus, j.id),
            ),
        })
        .collect();
    Ok(Json(HandCalibration {
        hand: p.hand,
        joints,
    }))
}
