//! A velocity command as a position target: the joint heads for the end of
//! its allowed range in the velocity's direction, at the velocity's speed
//! as its speed limit, so it moves at that speed and stops at its soft
//! limit (or calibrated range) at the latest; a velocity near 0 holds it
//! where it is. The request then goes through the same checks as every
//! target ([`super::targets::setpoint`]: enabled, range, soft limits,
//! speed limit); the stream's watchdog stops it when the commands stop.

use super::error::{ControlError, ControlResult};
use super::limits::JointLimits;
use super::targets::TargetRequest;
use crate::bus::handle::DeviceState;
use crate::hands::Calibration;
use crate::protocol::units::{self, MAX_ANGLE_DEG};
use crate::protocol::CtrlMode;

/// Below this (output °/s), a velocity is "stand still": a speed limit
/// that small would round to nothing on the wire, and a position target's
/// speed limit of 0 means the device's full speed.
pub(crate) const MIN_SPEED_DPS: f64 = 0.5;

/// How far inside the range end the target stays, degrees: the end itself
/// may round to just outside it through the calibration.
const END_MARGIN_DEG: f64 = 1e-6;

/// The target that moves joint `dev` at `dps` (°/s at the output shaft, in
/// its calibrated frame, signed); `field` names it in errors.
pub(crate) fn request(
    dev: &DeviceState,
    limits: &JointLimits,
    cal: &Calibration,
    dps: f64,
    field: &str,
) -> ControlResult<TargetRequest> {
    let vel_field = format!("{field}velocity");
    if !dps.is_finite() {
        return Err(ControlError::invalid(
            &vel_field,
            "a velocity must be finite",
        ));
    }
    if matches!(dev.mode, Some(CtrlMode::Speed | CtrlMode::Current)) {
        return Err(ControlError::conflict(
            "wrong-mode",
            "Joint not in position mode",
            format!(
                "joint {}: a velocity command drives a joint in position mode, within its \
                 soft limits (set its mode to position first)",
                dev.dev_id
            ),
        ));
    }
    let (lo, hi) = joint_range(limits, cal);
    if dps.abs() < MIN_SPEED_DPS {
        let here = measured_joint_deg(dev, cal).ok_or_else(|| {
            ControlError::invalid(
                &vel_field,
                format!("joint {}: no angle measured yet", dev.dev_id),
            )
        })?;
        return Ok(TargetRequest {
            position_deg: Some(here.clamp(lo + END_MARGIN_DEG, hi - END_MARGIN_DEG)),
            speed_dps: None,
        });
    }
    let end = if dps > 0.0 {
        hi - END_MARGIN_DEG
    } else {
        lo + END_MARGIN_DEG
    };
    Ok(TargetRequest {
        position_deg: Some(end),
        speed_dps: Some(dps.abs()),
    })
}

/// Where the joint may go, in its calibrated frame: its calibrated range,
/// the device's range and the soft limits, all at once.
fn joint_range(limits: &JointLimits, cal: &Calibration) -> (f64, f64) {
    let device = cal.range_to_joint((-MAX_ANGLE_DEG, MAX_ANGLE_DEG));
    let soft = cal.range_to_joint((limits.min_deg, limits.max_deg));
    let calibrated = cal.range_deg.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    (
        device.0.max(soft.0).max(calibrated.0),
        device.1.min(soft.1).min(calibrated.1),
    )
}

fn measured_joint_deg(dev: &DeviceState, cal: &Calibration) -> Option<f64> {
    let raw = super::device::measured_angle_raw(dev)?;
    Some(cal.to_joint(units::angle_deg(raw)))
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;
    use crate::protocol::Info01;

    fn dev(mode: CtrlMode) -> DeviceState {
        DeviceState {
            dev_id: 2,
            online: true,
            mode: Some(mode),
            info01: Some((
                Info01 {
                    soft_ver: 128,
                    angle: units::angle_to_raw(10.0).unwrap(),
                    ..Default::default()
                },
                Instant::now(),
            )),
            ..Default::default()
        }
    }

    fn limits() -> JointLimits {
        JointLimits {
            min_deg: -30.0,
            max_deg: 90.0,
            max_speed_dps: None,
        }
    }

    #[test]
    fn a_velocity_heads_for_the_soft_limit_at_its_speed() {
        let up = request(
            &dev(CtrlMode::Position),
            &limits(),
            &Calibration::IDENTITY,
            20.0,
            "",
        )
        .unwrap();
        assert!((up.position_deg.unwrap() - 90.0).abs() < 1e-3, "{up:?}");
        let dps = up.speed_dps.unwrap();
        assert!((dps - 20.0).abs() < 1e-9, "{dps}");
        let down = request(
            &dev(CtrlMode::Position),
            &limits(),
            &Calibration::IDENTITY,
            -5.0,
            "",
        )
        .unwrap();
        assert!((down.position_deg.unwrap() + 30.0).abs() < 1e-3, "{down:?}");
    }

    #[test]
    fn a_flipped_calibrated_joint_heads_for_its_own_ends() {
        // joint = -(device - 20): soft device -30..=90 is joint -70..=50,
        // narrowed by the calibrated range -10..=60 to -10..=50.
        let cal = Calibration {
            offset_deg: 20.0,
            flip: true,
            range_deg: Some((-10.0, 60.0)),
            homed_at_ms: None,
        };
        let d = dev(CtrlMode::Position);
        let up = request(&d, &limits(), &cal, 1.0, "").unwrap();
        assert!((up.position_deg.unwrap() - 50.0).abs() < 1e-3, "{up:?}");
        let down = request(&d, &limits(), &cal, -1.0, "").unwrap();
        assert!((down.position_deg.unwrap() + 10.0).abs() < 1e-3, "{down:?}");
        // The ends pass the same check every target does.
        for req in [up, down] {
            let sp = super::super::targets::setpoint(&d, &limits(), &cal, &req, "");
            assert!(sp.is_ok(), "{sp:?}");
        }
    }

    #[test]
    fn near_zero_holds_where_it_is_and_speed_mode_is_refused() {
        let hold = request(
            &dev(CtrlMode::Position),
            &limits(),
            &Calibration::IDENTITY,
            0.0,
            "",
        )
        .unwrap();
        assert!((hold.position_deg.unwrap() - 10.0).abs() < 0.01, "{hold:?}");
        assert_eq!(hold.speed_dps, None, "the default speed limit");
        let err = request(
            &dev(CtrlMode::Speed),
            &limits(),
            &Calibration::IDENTITY,
            3.0,
            "",
        )
        .unwrap_err();
        assert!(err.to_string().contains("position mode"), "{err}");
        let err = request(
            &dev(CtrlMode::Position),
            &limits(),
            &Calibration::IDENTITY,
            f64::NAN,
            "j.",
        )
        .unwrap_err();
        assert_eq!(err.field(), Some("j.velocity"));
    }
}
