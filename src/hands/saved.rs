//! What the state file holds, and reading it back checked: a file that
//! cannot be read or parsed is set aside and the daemon starts without it
//! (a daemon that cannot start cannot serve an e-stop either); a calibration
//! that could not be applied, or is not a calibration at all, is dropped on
//! its own and the rest of the file kept. Everything found is logged and
//! kept in [`LoadNotes`] for the API to show.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::SystemTime;

use serde::{Deserialize, Serialize};

use super::calibration::Calibration;
use super::pose::Pose;
use super::state_file::{StateFile, StateFileError};
use crate::protocol::is_device_id;

/// What the state file holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub(super) struct Saved {
    pub version: u32,
    /// hand → pose name → pose.
    pub poses: BTreeMap<String, BTreeMap<String, Pose>>,
    /// bus → device id → calibration (absent: the identity).
    #[serde(default)]
    pub calibration: BTreeMap<String, BTreeMap<u8, Calibration>>,
}

/// The file as read, before its calibrations are checked one by one.
#[derive(Debug, Deserialize)]
struct OnDisk {
    version: u32,
    poses: BTreeMap<String, BTreeMap<String, Pose>>,
    #[serde(default)]
    calibration: BTreeMap<String, BTreeMap<String, serde_json::Value>>,
}

/// What was wrong with the state file when the daemon started.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadNotes {
    /// The file could not be used and was renamed beside.
    pub set_aside: Option<SetAside>,
    /// The file could neither be used nor set aside: it is left as it is
    /// and nothing is saved over it.
    pub unusable: Option<String>,
    /// Calibrations dropped from the file.
    pub dropped: Vec<DroppedCalibration>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SetAside {
    pub moved_to: PathBuf,
    /// What was wrong with it.
    pub reason: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DroppedCalibration {
    pub bus: String,
    /// The id as the file has it (it may be no id at all).
    pub id: String,
    pub reason: String,
}

/// The saved state of `file` (the default when there is none or it cannot
/// be used) and what was wrong with it.
pub(super) fn load(file: &StateFile, now: SystemTime) -> (Saved, LoadNotes) {
    let mut notes = LoadNotes::default();
    let saved = match file.load::<OnDisk>() {
        Ok(None) => Saved::default(),
        Ok(Some(disk)) => checked(disk, &mut notes.dropped),
        Err(e) => {
            set_aside(file, now, &e, &mut notes);
            Saved::default()
        }
    };
    (saved, notes)
}

fn set_aside(file: &StateFile, now: SystemTime, error: &StateFileError, notes: &mut LoadNotes) {
    let from = file.path();
    let reason = reason(error);
    match file.set_aside(now) {
        Ok(to) => {
            tracing::error!(state_file = %from.display(), set_aside_as = %to.display(), %reason,
                "the state file cannot be used and is set aside: starting without saved poses and calibrations");
            notes.set_aside = Some(SetAside {
                moved_to: to,
                reason,
            });
        }
        Err(e) => {
            tracing::error!(state_file = %from.display(), %reason, set_aside_error = %e,
                "the state file cannot be used nor set aside: starting without saved poses and calibrations, saving none over it");
            notes.unusable = Some(format!("{reason}; setting it aside failed: {e}"));
        }
    }
}

/// The error without the path (the notes and the log say the path apart).
fn reason(error: &StateFileError) -> String {
    match error {
        StateFileError::Parse { source, .. } => format!("not a state file: {source}"),
        StateFileError::Io { source, .. } => format!("cannot be read: {source}"),
        other => other.to_string(),
    }
}

fn checked(disk: OnDisk, dropped: &mut Vec<DroppedCalibration>) -> Saved {
    let mut calibration: BTreeMap<String, BTreeMap<u8, Calibration>> = BTreeMap::new();
    for (bus, joints) in disk.calibration {
        for (id, value) in joints {
            match calibration_of(&id, value) {
                Ok((id, cal)) => {
                    calibration.entry(bus.clone()).or_default().insert(id, cal);
                }
                Err(reason) => {
                    tracing::warn!(bus = %bus, id = %id, %reason,
                        "a calibration in the state file is dropped: the joint reads uncalibrated");
                    dropped.push(DroppedCalibration {
                        bus: bus.clone(),
                        id,
                        reason,
                    });
                }
            }
        }
    }
    Saved {
        version: disk.version,
        poses: disk.poses,
        calibration,
    }
}

/// One calibration of the file, checked as one set through the API is.
fn calibration_of(id: &str, value: serde_json::Value) -> Result<(u8, Calibration), String> {
    let id = id
        .parse::<u8>()
        .ok()
        .filter(|id| is_device_id(*id))
        .ok_or_else(|| format!("`{id}` is not a device id"))?;
    let cal = Calibration::deserialize(value).map_err(|e| format!("not a calibration: {e}"))?;
    cal.checked()
        .map(|cal| (id, cal))
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_dir::TestDir;

    fn dir(name: &str) -> TestDir {
        TestDir::new(&format!("saved-{name}"))
    }

    #[test]
    fn a_file_that_does_not_parse_is_set_aside_whole() {
        let d = dir("bad");
        let file = StateFile::new(d.path());
        std::fs::write(file.path(), r#"{"version": 1, "poses": ["#).unwrap();
        let (saved, notes) = load(&file, SystemTime::now());
        assert_eq!(saved, Saved::default());
        let aside = notes.set_aside.expect("set aside");
        assert!(
            aside.reason.starts_with("not a state file"),
            "{}",
            aside.reason
        );
        assert_eq!(
            std::fs::read_to_string(&aside.moved_to).unwrap(),
            r#"{"version": 1, "poses": ["#
        );
        assert!(!file.path().exists());
        assert_eq!(notes.unusable, None);
    }

    #[test]
    fn each_bad_calibration_is_dropped_with_its_reason() {
        let d = dir("cal");
        let file = StateFile::new(d.path());
        let text = r#"{"version": 1, "poses": {"left": {"fist": {"thumb": 4.0}}},
            "calibration": {"l": {
                "1": {"offset_deg": 12.0},
                "2": {"offset_deg": 1e308},
                "3": {"range_deg": [60.0, -30.0]},
                "4": {"offset_deg": "twelve"},
                "0": {"offset_deg": 1.0},
                "x": {"offset_deg": 1.0}}}}"#;
        std::fs::write(file.path(), text).unwrap();
        let (saved, notes) = load(&file, SystemTime::now());
        assert_eq!(saved.poses["left"]["fist"]["thumb"], 4.0);
        let kept: Vec<u8> = saved.calibration["l"].keys().copied().collect();
        assert_eq!(kept, vec![1]);
        let why: BTreeMap<&str, &str> = notes
            .dropped
            .iter()
            .map(|c| (c.id.as_str(), c.reason.as_str()))
            .collect();
        assert!(why["2"].contains("offset_deg"), "{why:?}");
        assert!(why["3"].contains("range_deg"), "{why:?}");
        assert!(why["4"].starts_with("not a calibration"), "{why:?}");
        assert!(why["0"].contains("not a device id"), "{why:?}");
        assert!(why["x"].contains("not a device id"), "{why:?}");
        assert!(notes.set_aside.is_none() && file.path().exists());
    }

    #[test]
    fn a_file_that_cannot_be_read_is_set_aside_too() {
        let d = dir("unreadable");
        let file = StateFile::new(d.path());
        std::fs::create_dir_all(file.path().join("inside")).unwrap();
        let (saved, notes) = load(&file, SystemTime::now());
        assert_eq!(saved, Saved::default());
        let aside = notes.set_aside.expect("set aside");
        assert!(
            aside.reason.starts_with("cannot be read"),
            "{}",
            aside.reason
        );
        assert!(aside.moved_to.join("inside").is_dir());
    }

    #[test]
    fn a_file_that_cannot_be_set_aside_is_said_unusable() {
        // A state_dir that is a file: nothing in it can be read or renamed.
        let d = dir("stuck");
        let not_a_dir = d.join("file");
        std::fs::write(&not_a_dir, "x").unwrap();
        let (saved, notes) = load(&StateFile::new(&not_a_dir), SystemTime::now());
        assert_eq!(saved, Saved::default());
        assert_eq!(notes.set_aside, None);
        let why = notes.unusable.expect("unusable");
        assert!(why.contains("setting it aside failed"), "{why}");
    }
}
