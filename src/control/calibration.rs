//! Calibrations as the API shows and takes them ([`crate::hands::calibration`]
//! holds the arithmetic): a view shared by the device and calibration areas,
//! and saving one (checked, into the state file).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::control::error::{ControlError, ControlResult};
use crate::control::state::Control;
use crate::hands::Calibration;

/// A joint's calibration: `joint = sign · (device − offset_deg)`, sign −1
/// when `flip`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct CalibrationView {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    /// The device angle that is the joint's zero, degrees.
    #[schema(example = -42.5)]
    pub offset_deg: f64,
    /// The joint counts positive where the device counts negative.
    #[schema(example = false)]
    pub flip: bool,
    /// The usable range, joint degrees (`null`: the soft limits alone).
    #[schema(example = json!([0.0, 90.0]))]
    pub range_deg: Option<[f64; 2]>,
    /// When homing found the offset, Unix ms (`null`: set by hand, or never).
    #[schema(example = 1764072000000u64)]
    pub homed_at_ms: Option<u64>,
}

impl CalibrationView {
    pub(crate) fn new(bus: &str, id: u8, cal: &Calibration) -> Self {
        Self {
            bus: bus.to_owned(),
            id,
            offset_deg: cal.offset_deg,
            flip: cal.flip,
            range_deg: cal.range_deg.map(|(lo, hi)| [lo, hi]),
            homed_at_ms: cal.homed_at_ms,
        }
    }
}

/// A calibration to set: it replaces the joint's whole calibration (a field
/// left out takes its default: offset 0, no flip, no range).
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"offset_deg": -42.5, "flip": false, "range_deg": [0.0, 90.0]}))]
pub(crate) struct CalibrationRequest {
    /// The device angle that is to be the joint's zero, degrees (±255).
    #[schema(example = -42.5)]
    pub offset_deg: Option<f64>,
    #[schema(example = false)]
    pub flip: Option<bool>,
    /// The usable range, joint degrees, `[low, high]`.
    #[schema(example = json!([0.0, 90.0]))]
    pub range_deg: Option<[f64; 2]>,
}

impl CalibrationRequest {
    pub(crate) fn checked(&self) -> ControlResult<Calibration> {
        checked(Calibration {
            offset_deg: self.offset_deg.unwrap_or(0.0),
            flip: self.flip.unwrap_or(false),
            range_deg: self.range_deg.map(|[lo, hi]| (lo, hi)),
            homed_at_ms: None,
        })
    }
}

/// A calibration that could be applied, else 422 naming the field.
fn checked(cal: Calibration) -> ControlResult<Calibration> {
    cal.checked()
        .map_err(|e| ControlError::invalid(e.field(), e.to_string()))
}

/// Saves the calibration of joint `id` on `bus` in the state file (the
/// identity removes it); 422 when it could not be applied (checked here, so
/// every way of saving one is: a request, homing), 503 when it cannot be
/// written; either way nothing changed.
pub(crate) fn save(state: &Control, bus: &str, id: u8, cal: Calibration) -> ControlResult<()> {
    let cal = checked(cal)?;
    let store = state.hands().ok_or_else(|| {
        ControlError::state_unwritable(
            "this daemon keeps no saved state: the calibration was not set",
        )
    })?;
    store.set_calibration(bus, id, cal).map_err(|e| {
        ControlError::state_unwritable(format!("{e}; the calibration was not saved"))
    })?;
    tracing::info!(bus, id, offset_deg = cal.offset_deg, flip = cal.flip, range_deg = ?cal.range_deg,
        homed = cal.homed_at_ms.is_some(), "calibration saved");
    Ok(())
}
