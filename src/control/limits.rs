//! Soft limits per joint (min/max angle, max speed) from the daemon's config.
//! A target outside them is rejected with 422 naming the limit; nothing is
//! ever clamped silently.

use std::fmt::Display;

use serde::{Deserialize, Serialize};
use thiserror::Error;
use utoipa::ToSchema;

use super::error::ControlError;
use crate::hands::Calibration;
use crate::protocol::units::{self, output_deg_per_s, FirmwareVersion, MAX_ANGLE_DEG};

/// One rule of the `[[limit]]` table. Later rules override earlier ones
/// field by field, so a bus-wide default can be narrowed for single joints.
#[derive(Debug, Clone, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LimitRule {
    /// Bus name; absent = every bus.
    #[serde(default)]
    pub bus: Option<String>,
    /// Device ids; empty = every joint of the bus.
    #[serde(default)]
    pub ids: Vec<u8>,
    pub min_deg: Option<f64>,
    pub max_deg: Option<f64>,
    /// Largest output speed a target may ask for (speed limit in position
    /// mode, |speed| in speed mode), °/s.
    pub max_speed_dps: Option<f64>,
    /// Not read: rotor rpm gave way to output °/s. Kept so an old config is
    /// refused with the way to say it now, not as an unknown field.
    #[serde(default, skip_serializing)]
    pub max_rpm: Option<f64>,
}

/// The limits that apply to one joint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct JointLimits {
    #[schema(example = -90.0)]
    pub min_deg: f64,
    #[schema(example = 90.0)]
    pub max_deg: f64,
    /// Output °/s; absent: only the firmware's speed range applies.
    #[schema(example = 30.0)]
    pub max_speed_dps: Option<f64>,
}

impl Default for JointLimits {
    fn default() -> Self {
        Self {
            min_deg: -MAX_ANGLE_DEG,
            max_deg: MAX_ANGLE_DEG,
            max_speed_dps: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum LimitError {
    #[error("limit rule {rule}: {why}")]
    Bad { rule: usize, why: String },
}

/// Every configured rule, checked once at start-up.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SoftLimits {
    rules: Vec<LimitRule>,
}

impl SoftLimits {
    pub fn new(rules: Vec<LimitRule>) -> Result<Self, LimitError> {
        let limits = Self { rules };
        for (i, rule) in limits.rules.iter().enumerate() {
            let bad = |why: String| LimitError::Bad { rule: i + 1, why };
            for deg in [rule.min_deg, rule.max_deg].into_iter().flatten() {
                if !deg.is_finite() || deg.abs() > MAX_ANGLE_DEG {
                    return Err(bad(format!("angle {deg} is outside ±{MAX_ANGLE_DEG}°")));
                }
            }
            if let Some(rpm) = rule.max_rpm {
                return Err(bad(format!(
                    "max_rpm is no longer read: give max_speed_dps, the output speed in °/s \
                     ({rpm} rotor rpm is {:.1} °/s)",
                    output_deg_per_s(rpm)
                )));
            }
            if let Some(dps) = rule.max_speed_dps {
                if !dps.is_finite() || dps < 0.0 {
                    return Err(bad(format!("max_speed_dps {dps} must be ≥ 0")));
                }
            }
        }
        // A rule may set only one side; the combined result must still be a range.
        for (bus, id) in limits.mentioned_joints() {
            let j = limits.for_joint(bus.as_deref().unwrap_or(""), id);
            if j.min_deg > j.max_deg {
                return Err(LimitError::Bad {
                    rule: 0,
                    why: format!("joint {id}: min_deg {} > max_deg {}", j.min_deg, j.max_deg),
                });
            }
        }
        Ok(limits)
    }

    fn mentioned_joints(&self) -> Vec<(Option<String>, u8)> {
        let ids = self.rules.iter().flat_map(|r| r.ids.iter().copied());
        let ids: Vec<u8> = ids.chain(std::iter::once(0)).collect();
        let buses: Vec<Option<String>> = self.rules.iter().map(|r| r.bus.clone()).collect();
        buses
            .into_iter()
            .chain(std::iter::once(None))
            .flat_map(|b| ids.iter().map(move |id| (b.clone(), *id)))
            .collect()
    }

    /// The limits of joint `id` on `bus`: every matching rule applied in order.
    pub fn for_joint(&self, bus: &str, id: u8) -> JointLimits {
        let mut j = JointLimits::default();
        let matching = self.rules.iter().filter(|r| {
            r.bus.as_deref().map_or(true, |b| b == bus) && (r.ids.is_empty() || r.ids.contains(&id))
        });
        for rule in matching {
            j.min_deg = rule.min_deg.unwrap_or(j.min_deg);
            j.max_deg = rule.max_deg.unwrap_or(j.max_deg);
            j.max_speed_dps = rule.max_speed_dps.or(j.max_speed_dps);
        }
        j
    }
}

impl JointLimits {
    /// Refuses a position target given in the joint's calibrated degrees
    /// outside its calibrated range, the device's range or the soft limits
    /// (the last two told in joint degrees too); the device angle to send.
    /// `field` and `who` are written out only for an error: a teleop
    /// stream checks thousands of targets a second.
    pub fn check_joint_position(
        &self,
        cal: &Calibration,
        field: &dyn Display,
        deg: f64,
        who: &dyn Display,
    ) -> Result<f64, ControlError> {
        let (field, who) = (|| field.to_string(), || who.to_string());
        if !deg.is_finite() {
            let field = field();
            return Err(ControlError::invalid(
                &field,
                format!("{field} must be finite"),
            ));
        }
        if let Some((lo, hi)) = cal.range_deg.filter(|(lo, hi)| deg < *lo || deg > *hi) {
            return Err(ControlError::calibrated_range(
                &field(),
                deg,
                (lo, hi),
                &who(),
            ));
        }
        let device = cal.to_device(deg);
        if device.abs() > MAX_ANGLE_DEG {
            let range = cal.range_to_joint((-MAX_ANGLE_DEG, MAX_ANGLE_DEG));
            return Err(ControlError::out_of_range(&field(), deg, range, "deg"));
        }
        if device < self.min_deg || device > self.max_deg {
            let range = cal.range_to_joint((self.min_deg, self.max_deg));
            return Err(ControlError::soft_limit(
                &field(),
                deg,
                range,
                "deg",
                &who(),
            ));
        }
        Ok(device)
    }

    /// A speed a motion is to reach its goal at, °/s (a position target's
    /// speed limit, a grasp's closing or opening speed): at least the
    /// smallest the wire carries for firmware `fw` (below it the device is
    /// sent 0 and never arrives), and within the soft limit.
    pub fn check_motion_speed(
        &self,
        field: &dyn Display,
        dps: f64,
        fw: FirmwareVersion,
        who: &dyn Display,
    ) -> Result<(), ControlError> {
        let floor = output_deg_per_s(units::speed_rpm(1, fw));
        if !(dps.is_finite() && dps >= floor) {
            let top = self
                .max_speed_dps
                .unwrap_or_else(|| output_deg_per_s(fw.speed_base_rpm()));
            return Err(
                ControlError::out_of_range(&field.to_string(), dps, (floor, top), "°/s")
                    .with_detail(format!(
                "{field} = {dps} °/s for {who}: a motion needs at least {floor:.4} °/s, the \
                 smallest speed the wire carries, or it never arrives"
            )),
            );
        }
        self.check_speed(field, dps, who)
    }

    /// Refuses an output speed (°/s) whose magnitude exceeds `max_speed_dps`.
    pub fn check_speed(
        &self,
        field: &dyn Display,
        dps: f64,
        who: &dyn Display,
    ) -> Result<(), ControlError> {
        match self.max_speed_dps {
            Some(max) if dps.abs() > max => Err(ControlError::soft_limit(
                &field.to_string(),
                dps,
                (-max, max),
                "°/s",
                &who.to_string(),
            )),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(bus: Option<&str>, ids: &[u8], min: f64, max: f64, dps: Option<f64>) -> LimitRule {
        LimitRule {
            bus: bus.map(str::to_owned),
            ids: ids.to_vec(),
            min_deg: Some(min),
            max_deg: Some(max),
            max_speed_dps: dps,
            max_rpm: None,
        }
    }

    #[test]
    fn later_rules_narrow_earlier_ones() {
        let limits = SoftLimits::new(vec![
            rule(None, &[], -100.0, 100.0, Some(50.0)),
            rule(Some("left"), &[3], -10.0, 20.0, None),
        ])
        .unwrap();
        let j3 = limits.for_joint("left", 3);
        assert_eq!(
            (j3.min_deg, j3.max_deg, j3.max_speed_dps),
            (-10.0, 20.0, Some(50.0))
        );
        let other = limits.for_joint("right", 3);
        assert_eq!((other.min_deg, other.max_deg), (-100.0, 100.0));
        assert!(j3
            .check_joint_position(&Calibration::IDENTITY, &"position_deg", 25.0, &"joint 3")
            .is_err());
        assert!(j3
            .check_joint_position(&Calibration::IDENTITY, &"position_deg", 20.0, &"joint 3")
            .is_ok());
        let err = j3.check_speed(&"speed_dps", -60.0, &"joint 3").unwrap_err();
        let ControlError::Invalid { allowed, .. } = err else {
            panic!("a refused value, not {err:?}");
        };
        assert_eq!(allowed.map(|a| a.max), Some(50.0));
    }

    #[test]
    fn a_rotor_rpm_limit_is_refused_with_its_output_speed() {
        let old = LimitRule {
            max_rpm: Some(3000.0),
            ..Default::default()
        };
        let err = SoftLimits::new(vec![old]).unwrap_err().to_string();
        assert!(
            err.contains("max_speed_dps") && err.contains("31.6 °/s"),
            "{err}"
        );
    }

    #[test]
    fn inconsistent_rules_are_refused_at_start() {
        assert!(SoftLimits::new(vec![rule(None, &[], 10.0, -10.0, None)]).is_err());
        assert!(SoftLimits::new(vec![rule(None, &[], -300.0, 0.0, None)]).is_err());
        let one_sided = LimitRule {
            min_deg: Some(50.0),
            ..Default::default()
        };
        let narrowing = LimitRule {
            ids: vec![2],
            max_deg: Some(40.0),
            ..Default::default()
        };
        assert!(SoftLimits::new(vec![one_sided, narrowing]).is_err());
    }
}
