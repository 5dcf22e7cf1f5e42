//! ROS 2 messages in CDR, encoded and decoded in one place: what MCAP
//! recordings hold and what the ROS 2 bridge takes and gives.
//!
//! # Layout
//! - [`cdr`]: CDR little-endian: the writer, the reader, their error.
//! - [`topics`]: the messages recordings and the bridge both carry
//!   (`JointState`, `String`, `DiagnosticArray`) and their definitions.
//! - `bridge`: the bridge's own (`std_srvs` SetBool and Trigger,
//!   `JointTrajectory`, `Log`, `GripperCommand`).

#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
pub(crate) mod bridge;
pub mod cdr;
pub mod topics;

pub use cdr::CdrError;
pub use topics::{
    diagnostic_array_cdr, string_cdr, string_from_cdr, DiagnosticStatus, JointState,
    JOINT_STATE_MSG, STRING_MSG,
};
