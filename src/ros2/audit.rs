//! ROS 2's commands in the audit. ROS 2 carries no tokens: whoever reaches
//! the Zenoh network acts with the operate scope (docs/security.md), and
//! its commands are told as [`CALLER`], with the service or topic they
//! came on.

use crate::control::audit::Command;
use crate::control::Control;
use crate::record::joint_states::Scope;

/// The name ROS 2's commands are told with.
pub(super) const CALLER: &str = "ros2";

/// Tells one command that came on `what` (a service or topic) and how it
/// ended, to `bus`'s events (`None`: every bus's, as a hand's commands).
pub(super) fn tell(state: &Control, bus: Option<&str>, what: &str, outcome: &str) {
    let what = format!("ROS 2 {what}");
    let cmd = Command {
        by: CALLER,
        kind: &what,
        what: &what,
        outcome,
    };
    state.tell(&cmd, bus);
}

/// The bus a scope's commands are told to (a hand's: every bus).
pub(super) fn bus(scope: &Scope) -> Option<&str> {
    match scope {
        Scope::Bus(bus) => Some(bus),
        Scope::Hand { .. } => None,
    }
}

/// The namespace of a scope: its bus or its hand.
pub(super) fn namespace(scope: &Scope) -> &str {
    match scope {
        Scope::Bus(bus) => bus,
        Scope::Hand { name, .. } => name,
    }
}
