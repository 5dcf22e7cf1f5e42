//! Where a release opens each finger still in the grasp to: the hand's
//! pose, or an angle from where the finger is, or back to where it
//! started; every goal checked against the finger's limits before any
//! finger moves.

use super::admit::here_joint_deg;
use super::request::ReleaseRequest;
use crate::control::books::grasps::{FingerGrasp, Job};
use crate::control::error::{ControlError, ControlResult};
use crate::control::state::Control;

/// A release goal may lie this far on the closing side of where the
/// finger stands (it settles a little past its goal): further is no
/// release.
const CLOSING_SLACK_DEG: f64 = 1.0;

/// Each finger's opening goal (device degrees), in job order; `None` for
/// a finger no longer in the grasp.
pub(super) fn open_goals(
    state: &Control,
    job: &Job,
    req: &ReleaseRequest,
    speed_dps: f64,
) -> ControlResult<Vec<Option<f64>>> {
    if req.pose.is_some() && req.open_deg.is_some() {
        return Err(ControlError::invalid(
            "pose",
            "give `pose` or `open_deg`, not both",
        ));
    }
    let pose = match &req.pose {
        Some(name) => Some(
            state
                .hands()
                .and_then(|s| s.pose(&job.hand, name))
                .ok_or_else(|| {
                    ControlError::not_found(
                        "unknown-pose",
                        format!("hand `{}` has no pose named `{name}`", job.hand),
                    )
                })?,
        ),
        None => None,
    };
    if let Some(d) = req.open_deg {
        if !(d.is_finite() && d > 0.0 && d <= 180.0) {
            return Err(ControlError::out_of_range(
                "open_deg",
                d,
                (0.0, 180.0),
                "deg",
            ));
        }
    }
    job.slots
        .iter()
        .map(|slot| {
            let f = crate::control::books::lock::lock(slot).clone();
            if !f.state.live() {
                return Ok(None);
            }
            open_speed(state, &f, speed_dps)?;
            open_goal(state, &f, pose.as_ref(), req.open_deg).map(Some)
        })
        .collect()
}

/// The opening speed, checked for one finger as every motion speed is.
fn open_speed(state: &Control, f: &FingerGrasp, speed_dps: f64) -> ControlResult<()> {
    let snap = state.bus(&f.bus)?.snapshot();
    let fw = snap
        .devices
        .get(&f.id)
        .map(crate::control::device::firmware_of)
        .unwrap_or_default();
    state.limits(&f.bus, f.id).check_motion_speed(
        &"speed_dps",
        speed_dps,
        fw,
        &format!("joint `{}`", f.joint),
    )
}

/// Where one finger opens to (device degrees), checked against its limits.
fn open_goal(
    state: &Control,
    f: &FingerGrasp,
    pose: Option<&crate::hands::Pose>,
    open_deg: Option<f64>,
) -> ControlResult<f64> {
    let cal = state.calibration(&f.bus, f.id);
    let soft = state.limits(&f.bus, f.id);
    let here = here_joint_deg(state, &f.bus, f.id, &cal)?;
    let field = format!("fingers.{}", f.joint);
    // The way the finger closed (from where it started towards its
    // limit); opening is the other way, whatever side of its limit it
    // settled on.
    let closing = if f.close_to_deg >= f.start_deg {
        1.0
    } else {
        -1.0
    };
    let goal = match (pose, open_deg) {
        (Some(p), _) => *p.get(&f.joint).ok_or_else(|| {
            ControlError::invalid(
                "pose",
                format!("the pose has no angle for joint `{}`", f.joint),
            )
        })?,
        (None, Some(d)) => here - closing * d,
        (None, None) => f.start_deg,
    };
    if (goal - here) * closing > CLOSING_SLACK_DEG {
        return Err(ControlError::invalid(
            &field,
            format!(
                "joint `{}`: {goal:.1}° is further closed than where it is ({here:.1}°); \
                 a release opens",
                f.joint
            ),
        ));
    }
    soft.check_joint_position(&cal, &field, goal, &format!("joint `{}`", f.joint))
}
