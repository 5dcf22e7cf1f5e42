//! A joint's calibration: where its zero is, which way it turns, and the
//! range it may use. Applied at the API edge in both directions: every
//! angle a user gives is a *joint* angle, turned into the device's angle
//! before it is checked against the soft limits and sent; every angle and
//! speed the API reports is turned back. The device's own zero is never
//! touched by a calibration (`rezero` does that, when asked).
//!
//! `joint = sign · (device − offset)`, `device = offset + sign · joint`,
//! with `sign = −1` when flipped. An affine map, so a path planned in one
//! frame is the same shape in the other and its extremes stay extremes.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::protocol::units::MAX_ANGLE_DEG;

/// One joint's calibration (the identity by default).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// The device angle, degrees, that is the joint's zero.
    #[serde(default)]
    pub offset_deg: f64,
    /// The joint turns positive where the device turns negative.
    #[serde(default)]
    pub flip: bool,
    /// The usable range, joint degrees; absent: the soft limits alone.
    #[serde(default)]
    pub range_deg: Option<(f64, f64)>,
    /// When homing found the offset (Unix ms); absent when it was set by hand.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub homed_at_ms: Option<u64>,
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum CalibrationError {
    // `{:?}`: a huge value reads `1e308`, not 309 digits.
    #[error("offset_deg = {0:?} must be a finite angle within ±{MAX_ANGLE_DEG}° (the device's position range)")]
    Offset(f64),
    #[error("range_deg = [{0:?}, {1:?}] must be two finite angles, the first below the second")]
    Range(f64, f64),
}

impl CalibrationError {
    /// The request field it is about.
    pub fn field(&self) -> &'static str {
        match self {
            Self::Offset(_) => "offset_deg",
            Self::Range(..) => "range_deg",
        }
    }
}

impl Calibration {
    pub const IDENTITY: Self = Self {
        offset_deg: 0.0,
        flip: false,
        range_deg: None,
        homed_at_ms: None,
    };

    /// Refuses what could not be applied.
    pub fn checked(self) -> Result<Self, CalibrationError> {
        if !self.offset_deg.is_finite() || self.offset_deg.abs() > MAX_ANGLE_DEG {
            return Err(CalibrationError::Offset(self.offset_deg));
        }
        if let Some((lo, hi)) = self.range_deg {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(CalibrationError::Range(lo, hi));
            }
        }
        Ok(self)
    }

    pub fn is_identity(&self) -> bool {
        self.offset_deg == 0.0 && !self.flip && self.range_deg.is_none()
    }

    /// +1, or −1 when flipped: multiplies speeds and currents.
    pub fn sign(&self) -> f64 {
        if self.flip {
            -1.0
        } else {
            1.0
        }
    }

    /// A device angle as the joint's angle.
    pub fn to_joint(&self, device_deg: f64) -> f64 {
        self.sign() * (device_deg - self.offset_deg)
    }

    /// A joint angle as the device's angle.
    pub fn to_device(&self, joint_deg: f64) -> f64 {
        self.offset_deg + self.sign() * joint_deg
    }

    /// A range of device angles as joint angles, low end first.
    pub fn range_to_joint(&self, (lo, hi): (f64, f64)) -> (f64, f64) {
        let (a, b) = (self.to_joint(lo), self.to_joint(hi));
        (a.min(b), a.max(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_directions_undo_each_other() {
        for cal in [
            Calibration::IDENTITY,
            Calibration {
                offset_deg: 12.5,
                ..Calibration::IDENTITY
            },
            Calibration {
                offset_deg: -40.0,
                flip: true,
                ..Calibration::IDENTITY
            },
        ] {
            for deg in [-200.0, -3.25, 0.0, 17.0, 90.0] {
                assert!((cal.to_device(cal.to_joint(deg)) - deg).abs() < 1e-12);
                assert!((cal.to_joint(cal.to_device(deg)) - deg).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_flipped_joint_counts_the_other_way_from_its_offset() {
        let cal = Calibration {
            offset_deg: 30.0,
            flip: true,
            ..Calibration::IDENTITY
        };
        assert_eq!(cal.to_joint(30.0), 0.0);
        assert_eq!(cal.to_joint(20.0), 10.0);
        assert_eq!(cal.to_device(45.0), -15.0);
        assert_eq!(cal.range_to_joint((-90.0, 90.0)), (-60.0, 120.0));
        assert_eq!(cal.sign(), -1.0);
    }

    #[test]
    fn what_cannot_be_applied_is_refused() {
        let bad_offset = Calibration {
            offset_deg: f64::NAN,
            ..Calibration::IDENTITY
        };
        assert_eq!(bad_offset.checked().unwrap_err().field(), "offset_deg");
        let far = Calibration {
            offset_deg: 300.0,
            ..Calibration::IDENTITY
        };
        let far = far.checked().unwrap_err().to_string();
        assert!(far.contains("= 300.0 ") && far.contains("±255°"), "{far}");
        let huge = Calibration {
            offset_deg: 1e308,
            ..Calibration::IDENTITY
        };
        let huge = huge.checked().unwrap_err().to_string();
        assert!(huge.starts_with("offset_deg = 1e308 must"), "{huge}");
        let upside_down = Calibration {
            range_deg: Some((10.0, -10.0)),
            ..Calibration::IDENTITY
        };
        assert_eq!(upside_down.checked().unwrap_err().field(), "range_deg");
        assert!(Calibration::IDENTITY.is_identity());
    }
}
