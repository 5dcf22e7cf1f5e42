//! What a grasp is asked for (its request and its release), the pose
//! it closes to by default and how a joint already in a grasp is
//! refused: what the job, its admission and its release all speak.

use serde::Deserialize;
use utoipa::ToSchema;

use crate::control::books::grasps::Busy;
use crate::control::error::ControlError;

/// The pose a finger closes to by default.
pub(crate) const CLOSED_POSE: &str = "closed";
/// One finger of the hand, by its joint name, and where it closes to.
#[derive(Debug, Clone, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct GraspJoint {
    /// The joint's name in the hand.
    #[schema(example = "index")]
    pub joint: String,
    /// Where it closes to at most, degrees (calibrated frame); default:
    /// the hand's pose `closed`, else the top of the joint's allowed range.
    /// Fingers close towards higher angles: a limit below where the finger
    /// stands is refused (`would-open`).
    #[schema(example = 90.0)]
    pub close_to_deg: Option<f64>,
}

/// How to grasp.
#[derive(Debug, Clone, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"speed_dps": 30.0, "hold_current_a": 0.2}))]
pub(crate) struct GraspRequest {
    /// Closing speed at the output, °/s (0 < s ≤ 180, within each
    /// finger's soft speed limit, and no slower than the wire carries).
    #[schema(example = 30.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub speed_dps: f64,
    /// The force each finger holds with, as a q current, A (0 < I ≤ 5.625,
    /// below the joint's own current limit and its protection level).
    #[schema(example = 0.2, exclusive_minimum = 0.0, maximum = 5.625)]
    pub hold_current_a: f64,
    /// The rise of q current over what the finger draws moving freely that
    /// counts as contact, A (0.02 ≤ t < hold_current_a: below 0.02 the
    /// current's noise reads as contact; default 30 % of hold_current_a,
    /// at least 0.02).
    #[schema(example = 0.06, minimum = 0.02)]
    pub contact_threshold_a: Option<f64>,
    /// The fingers (1..=64, each once); default: every joint of the hand.
    pub joints: Option<Vec<GraspJoint>>,
}

/// How to let go.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"open_deg": 20.0}))]
pub(crate) struct ReleaseRequest {
    /// Open to this pose of the hand (its angle for each finger).
    #[schema(example = "open")]
    pub pose: Option<String>,
    /// Open each finger by this much from where it is, degrees (0 < d ≤ 180).
    #[schema(example = 20.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub open_deg: Option<f64>,
    /// Opening speed, °/s (default: the closing speed), checked as the
    /// closing speed is.
    #[schema(example = 30.0, exclusive_minimum = 0.0, maximum = 180.0)]
    pub speed_dps: Option<f64>,
}

/// 409 naming the grasp that has the joint.
pub(crate) fn busy(b: &Busy) -> ControlError {
    ControlError::conflict(
        "grasp-running",
        "Joint already grasping",
        format!(
            "joint {} of bus `{}` is in grasp {} (GET /api/v1/grasps/{}): one grasp per joint \
             at a time; release or stop it first",
            b.id, b.bus, b.job, b.job
        ),
    )
}
