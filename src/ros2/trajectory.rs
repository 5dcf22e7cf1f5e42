//! A `trajectory_msgs/msg/JointTrajectory` as a move request (what `POST
//! /api/v1/moves` takes): its points as waypoints at their
//! `time_from_start`, minimum jerk between them (each point reached at rest;
//! the points' velocities and accelerations are not used). Pure.

use super::commands::Refused;
use crate::control::moves::{MoveJoint, MoveRequest, WaypointRequest};
use crate::control::JointRef;
use crate::motion::Method;
use crate::rosmsg::bridge::JointTrajectory;

/// The move that runs through the trajectory's points (rad → degrees, in
/// each joint's calibrated frame). A first point at `time_from_start` 0
/// is where the trajectory starts, not somewhere to go: it is left out
/// (the move starts where each joint is).
pub(crate) fn move_request(
    t: &JointTrajectory,
    joints: Vec<JointRef>,
) -> Result<MoveRequest, Refused> {
    if joints.is_empty() {
        return Err(Refused::new("malformed", "no joint named"));
    }
    let skip = usize::from(t.points.first().is_some_and(|p| p.time_from_start_ns == 0));
    let points = &t.points[skip..];
    if points.is_empty() {
        return Err(Refused::new("malformed", "no point to go to"));
    }
    let mut waypoints = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        if p.positions.len() != joints.len() {
            return Err(Refused::new(
                "malformed",
                format!(
                    "point {} has {} positions for {} joints",
                    i + skip,
                    p.positions.len(),
                    joints.len()
                ),
            ));
        }
        waypoints.push(WaypointRequest {
            at_ms: p.time_from_start_ns as f64 / 1e6,
            positions_deg: p.positions.iter().map(|r| r.to_degrees()).collect(),
        });
    }
    Ok(MoveRequest {
        joints: joints
            .into_iter()
            .map(|j| MoveJoint {
                bus: Some(j.bus),
                id: Some(i64::from(j.id)),
                hand: None,
                joint: None,
                position_deg: None,
            })
            .collect(),
        duration_ms: None,
        max_velocity_dps: None,
        max_acceleration_dps2: None,
        method: Some(Method::MinJerk),
        waypoints: Some(waypoints),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosmsg::bridge::TrajectoryPoint;

    fn point(positions: Vec<f64>, ms: i64) -> TrajectoryPoint {
        TrajectoryPoint {
            positions,
            time_from_start_ns: ms * 1_000_000,
            ..TrajectoryPoint::default()
        }
    }

    fn joints(n: u8) -> Vec<JointRef> {
        (1..=n)
            .map(|id| JointRef {
                bus: "sim0".into(),
                id,
            })
            .collect()
    }

    #[test]
    fn points_become_waypoints_in_degrees_at_their_times() {
        let t = JointTrajectory {
            joint_names: vec!["a".into(), "b".into()],
            points: vec![
                point(vec![0.0, 0.0], 0),
                point(vec![std::f64::consts::FRAC_PI_2, -0.5], 400),
                point(vec![0.25, 0.0], 1_250),
            ],
            ..JointTrajectory::default()
        };
        let req = move_request(&t, joints(2)).unwrap();
        let w = req.waypoints.unwrap();
        assert_eq!(w.len(), 2, "the point at 0 is the start, left out");
        assert_eq!(w[0].at_ms, 400.0);
        assert!((w[0].positions_deg[0] - 90.0).abs() < 1e-9);
        assert_eq!(w[1].at_ms, 1_250.0);
        assert_eq!(req.joints[1].id, Some(2));
        assert_eq!(req.joints[1].bus.as_deref(), Some("sim0"));
    }

    #[test]
    fn a_point_of_the_wrong_width_or_none_at_all_is_refused() {
        let t = JointTrajectory {
            points: vec![point(vec![0.1], 100), point(vec![0.1, 0.2], 200)],
            ..JointTrajectory::default()
        };
        let err = move_request(&t, joints(2)).unwrap_err();
        assert_eq!(err.cause, "malformed");
        assert!(
            err.why.contains("point 0 has 1 positions for 2 joints"),
            "{}",
            err.why
        );
        let only_start = JointTrajectory {
            points: vec![point(vec![0.0], 0)],
            ..JointTrajectory::default()
        };
        assert!(move_request(&only_start, joints(1)).is_err());
    }
}
