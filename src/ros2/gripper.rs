//! A hand's grasp in ROS 2 terms, decided apart from any I/O: a
//! `control_msgs/msg/GripperCommand` on `<hand>/gripper_command` as the
//! grasp request REST's `POST /api/v1/hands/{hand}/grasp` takes, and a
//! grasp job as the `diagnostic_msgs/msg/DiagnosticStatus` list that
//! `<hand>/grasp_state` carries.
//!
//! The command: `position` (rad, the joints' calibrated frame) is the
//! closing limit of every finger of the hand, NaN each finger's default
//! (the hand's pose `closed`, else the top of its allowed range, as REST
//! without `close_to_deg`); `max_effort` is the hold current in A (the
//! unit of `joint_states`' effort). Fingers close towards higher angles:
//! a limit below where a finger stands would open it, which the control
//! core refuses (`would-open`, naming the finger) as it does for REST and
//! the WebSocket. The closing speed is `[ros2] grasp_speed_dps` (the
//! message has none).

use super::commands::Refused;
use crate::control::books::grasps::{FingerState, GraspView};
use crate::control::grasp::{GraspJoint, GraspRequest};
use crate::rosmsg::bridge::GripperCommand;
use crate::rosmsg::DiagnosticStatus;

/// One finger of the hand: its joint name.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FingerNow {
    pub name: String,
}

/// The grasp request `cmd` asks of a hand with `fingers`, closing at
/// `speed_dps`; or why it is refused whole. The hold current's range and
/// each limit's soft limits are the control core's to check (REST's
/// checks, REST's words).
pub(crate) fn grasp_request(
    cmd: &GripperCommand,
    fingers: &[FingerNow],
    speed_dps: f64,
) -> Result<GraspRequest, Refused> {
    if !cmd.max_effort.is_finite() {
        return Err(Refused::new(
            "not-finite",
            format!(
                "max_effort = {}: give the hold current in A",
                cmd.max_effort
            ),
        ));
    }
    let joints = if cmd.position.is_nan() {
        // Every finger of the hand to its own default limit.
        None
    } else if !cmd.position.is_finite() {
        return Err(Refused::new(
            "not-finite",
            format!(
                "position = {}: give the closing limit in rad (NaN: each finger's default)",
                cmd.position
            ),
        ));
    } else {
        let close_to = cmd.position.to_degrees();
        Some(
            fingers
                .iter()
                .map(|f| GraspJoint {
                    joint: f.name.clone(),
                    close_to_deg: Some(close_to),
                })
                .collect(),
        )
    };
    Ok(GraspRequest {
        speed_dps,
        hold_current_a: cmd.max_effort,
        contact_threshold_a: None,
        joints,
    })
}

/// A finger state's name, as REST writes it (`no_contact`, ...).
fn state_name(s: FingerState) -> String {
    serde_json::to_value(s)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{s:?}"))
}

/// OK while it goes as asked, WARN when it found nothing or lost what it
/// held, ERROR when something ended it or it could not start.
fn level(s: FingerState) -> u8 {
    match s {
        FingerState::NoContact | FingerState::Lost => 1,
        FingerState::Aborted | FingerState::Failed => 2,
        _ => 0,
    }
}

fn rad(deg: Option<f64>) -> String {
    deg.map_or_else(String::new, |d| format!("{:.4}", d.to_radians()))
}

/// The grasp as `grasp_state` carries it: first the job (`jointd: grasp
/// <hand>`: its id, `running` or `done`, the hold current), then one
/// status per finger (`jointd: grasp <hand> <joint>`, `hardware_id`
/// `<bus>/<id>`, message = its state) with `state`, `contact`,
/// `contact_rad`, `q_current_a`, `close_to_rad`, `start_rad`,
/// `current_limit_restored` and `reason`. Angles in rad, currents in A.
pub(crate) fn statuses(view: &GraspView) -> Vec<DiagnosticStatus> {
    let worst = view
        .fingers
        .iter()
        .map(|f| level(f.state))
        .max()
        .unwrap_or(0);
    let mut out = vec![DiagnosticStatus {
        level: worst,
        name: format!("jointd: grasp {}", view.hand),
        message: format!("grasp {} {}", view.id, view.state),
        hardware_id: String::new(),
        values: vec![
            ("grasp_id".into(), view.id.to_string()),
            ("state".into(), view.state.to_owned()),
            (
                "speed_rad_s".into(),
                format!("{:.4}", view.settings.speed_dps.to_radians()),
            ),
            (
                "hold_current_a".into(),
                format!("{:.3}", view.settings.hold_current_a),
            ),
            (
                "contact_threshold_a".into(),
                format!("{:.3}", view.settings.contact_threshold_a),
            ),
        ],
    }];
    for f in &view.fingers {
        let state = state_name(f.state);
        out.push(DiagnosticStatus {
            level: level(f.state),
            name: format!("jointd: grasp {} {}", view.hand, f.joint),
            message: state.clone(),
            hardware_id: format!("{}/{}", f.bus, f.id),
            values: vec![
                ("state".into(), state),
                ("contact".into(), f.contact.to_string()),
                ("contact_rad".into(), rad(f.contact_deg)),
                (
                    "q_current_a".into(),
                    f.q_current_a
                        .map_or_else(String::new, |q| format!("{q:.3}")),
                ),
                ("close_to_rad".into(), rad(Some(f.close_to_deg))),
                ("start_rad".into(), rad(Some(f.start_deg))),
                (
                    "current_limit_restored".into(),
                    f.current_limit_restored.to_string(),
                ),
                ("reason".into(), f.reason.clone().unwrap_or_default()),
            ],
        });
    }
    out
}

/// What a new `grasp_state` is published for: the job's and each
/// finger's state, contact, limit restored and reason, and the current
/// to 10 mA (finer is the reading's noise).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Change(Vec<String>);

pub(crate) fn change(view: &GraspView) -> Change {
    let mut key = vec![format!("{} {}", view.id, view.state)];
    key.extend(view.fingers.iter().map(|f| {
        format!(
            "{:?} {} {:?} {:?} {} {:?}",
            f.state,
            f.contact,
            f.contact_deg.map(f64::to_bits),
            f.q_current_a.map(|q| (q * 100.0).round() as i64),
            f.current_limit_restored,
            f.reason
        )
    }));
    Change(key)
}

/// A service's answer about a grasp that ended: success when it ended
/// (`done`) with every finger's limit read back restored; the message
/// names each finger's state.
pub(crate) fn ended(view: &GraspView, verb: &str) -> (bool, String) {
    let done = view.state == "done";
    let restored = view.fingers.iter().all(|f| f.current_limit_restored);
    let each: Vec<String> = view
        .fingers
        .iter()
        .map(|f| {
            let limit = if f.current_limit_restored {
                "limit restored"
            } else {
                "limit NOT restored"
            };
            format!("{} {} ({limit})", f.joint, state_name(f.state))
        })
        .collect();
    let head = if done {
        format!("grasp {} {verb}", view.id)
    } else {
        format!("grasp {} still running after the wait", view.id)
    };
    (done && restored, format!("{head}: {}", each.join(", ")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::books::grasps::{FingerGrasp, GraspSettings};

    fn fingers(here: &[Option<f64>]) -> Vec<FingerNow> {
        (0..here.len())
            .map(|i| FingerNow {
                name: format!("f{i}"),
            })
            .collect()
    }

    fn cmd(position: f64, max_effort: f64) -> GripperCommand {
        GripperCommand {
            position,
            max_effort,
        }
    }

    #[test]
    fn a_command_is_a_grasp_of_every_finger_to_its_position() {
        let req = grasp_request(&cmd(0.5, 0.2), &fingers(&[Some(0.0), None]), 30.0).unwrap();
        assert_eq!(req.speed_dps, 30.0);
        assert_eq!(req.hold_current_a, 0.2);
        assert!(req.contact_threshold_a.is_none(), "the core's default");
        let joints = req.joints.unwrap();
        assert_eq!(joints.len(), 2);
        assert_eq!(joints[1].joint, "f1");
        let deg = joints[0].close_to_deg.unwrap();
        assert!((deg - 28.6479).abs() < 1e-3, "{deg}");
        // NaN: every finger to its own default limit.
        let req = grasp_request(&cmd(f64::NAN, 0.2), &fingers(&[Some(50.0)]), 30.0).unwrap();
        assert!(req.joints.is_none());
    }

    #[test]
    fn a_number_that_is_none_is_refused() {
        // (A limit behind a finger is the core's to refuse: would-open.)
        for bad in [
            cmd(0.5, f64::NAN),
            cmd(f64::INFINITY, 0.2),
            cmd(0.5, f64::NEG_INFINITY),
        ] {
            assert_eq!(
                grasp_request(&bad, &fingers(&[Some(0.0)]), 30.0)
                    .unwrap_err()
                    .cause,
                "not-finite",
                "{bad:?}"
            );
        }
        // A negative or zero hold is the core's to refuse (REST's words).
        assert_eq!(
            grasp_request(&cmd(0.5, -0.1), &fingers(&[Some(0.0)]), 30.0)
                .unwrap()
                .hold_current_a,
            -0.1
        );
    }

    fn finger(joint: &str, state: FingerState, contact_deg: Option<f64>) -> FingerGrasp {
        FingerGrasp {
            bus: "sim0".into(),
            id: 1,
            joint: joint.into(),
            state,
            contact: contact_deg.is_some(),
            contact_deg,
            contact_after_ms: None,
            q_current_a: Some(0.2012),
            close_to_deg: 25.0,
            start_deg: 0.0,
            previous_current_limit_a: Some(0.75),
            current_limit_restored: false,
            reason: None,
        }
    }

    fn view(fingers: Vec<FingerGrasp>) -> GraspView {
        GraspView {
            id: 3,
            hand: "right".into(),
            state: "running",
            settings: GraspSettings {
                speed_dps: 30.0,
                hold_current_a: 0.2,
                contact_threshold_a: 0.06,
            },
            fingers,
        }
    }

    #[test]
    fn the_state_is_one_status_for_the_grasp_and_one_per_finger_in_rad() {
        let v = view(vec![
            finger("a", FingerState::Holding, Some(15.0)),
            finger("b", FingerState::NoContact, None),
        ]);
        let s = statuses(&v);
        assert_eq!(s.len(), 3);
        assert_eq!(s[0].name, "jointd: grasp right");
        assert_eq!(s[0].message, "grasp 3 running");
        assert_eq!(s[0].level, 1, "the worst finger's");
        assert_eq!(s[1].name, "jointd: grasp right a");
        assert_eq!((s[1].level, s[1].message.as_str()), (0, "holding"));
        assert_eq!(s[1].hardware_id, "sim0/1");
        let value = |i: usize, k: &str| {
            s[i].values
                .iter()
                .find(|(key, _)| key == k)
                .map(|(_, v)| v.clone())
                .unwrap()
        };
        assert_eq!(value(1, "contact"), "true");
        assert_eq!(value(1, "contact_rad"), "0.2618");
        assert_eq!(value(1, "q_current_a"), "0.201");
        assert_eq!(value(1, "close_to_rad"), "0.4363");
        assert_eq!((s[2].level, s[2].message.as_str()), (1, "no_contact"));
        assert_eq!(value(2, "contact"), "false");
        assert_eq!(value(2, "contact_rad"), "");
    }

    #[test]
    fn a_change_is_a_state_or_ten_milliamperes_not_noise() {
        let base = view(vec![finger("a", FingerState::Holding, Some(15.0))]);
        let mut noisy = base.clone();
        noisy.fingers[0].q_current_a = Some(0.2031);
        assert_eq!(change(&base), change(&noisy));
        let mut more = base.clone();
        more.fingers[0].q_current_a = Some(0.25);
        assert_ne!(change(&base), change(&more));
        let mut lost = base.clone();
        lost.fingers[0].state = FingerState::Lost;
        assert_ne!(change(&base), change(&lost));
        let mut done = base.clone();
        done.state = "done";
        assert_ne!(change(&base), change(&done));
    }

    #[test]
    fn a_service_succeeds_once_the_grasp_ended_with_every_limit_restored() {
        let mut v = view(vec![finger("a", FingerState::Released, Some(15.0))]);
        let (ok, msg) = ended(&v, "released");
        assert!(!ok, "still running: {msg}");
        v.state = "done";
        assert!(!ended(&v, "released").0, "limit not restored");
        v.fingers[0].current_limit_restored = true;
        let (ok, msg) = ended(&v, "released");
        assert!(ok);
        assert_eq!(msg, "grasp 3 released: a released (limit restored)");
    }
}
