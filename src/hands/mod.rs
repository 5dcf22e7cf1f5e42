//! Named hands and their poses: `[[hand]]` in the config names a set of
//! joints, possibly on several buses, each with a joint name; poses
//! (`open`, `fist`, ...) are joint angles by name, saved in the state file
//! (`state_dir`) so they survive restarts.
//!
//! - [`hand`]: the hands from the config, checked.
//! - [`state_file`]: the state file, written atomically, set aside when bad.
//! - [`saved`]: what it holds, read back checked.
//! - [`calibration`]: a joint's offset, direction and range.
//! - [`pose`]: a pose as a request gives it, each joint named once.
//! - `store`: [`StateStore`], what users saved (poses, calibrations), kept in memory and
//!   written to the state file on every change.

pub mod calibration;
pub mod hand;
pub mod pose;
pub mod saved;
pub mod state_file;
mod store;

pub use calibration::{Calibration, CalibrationError};
pub use hand::{resolve, Hand, HandConfig, HandError, HandJoint, HandJoints, Ids};
pub use pose::Pose;
pub use saved::{DroppedCalibration, LoadNotes, SetAside};
pub use state_file::{StateFile, StateFileError};
pub use store::StateStore;
