//! Named hands and their poses: `[[hand]]` in the config names a set of
//! joints, possibly on several buses, each with a joint name; poses
//! (`open`, `fist`, ...) are joint angles by name, saved in the state file
//! (`state_dir`) so they survive restarts.
//!
//! - [`state_file`]: the state file, written atomically, set aside when bad.
//! - [`saved`]: what it holds, read back checked.
//! - [`calibration`]: a joint's offset, direction and range.
//! - [`pose`]: a pose as a request gives it, each joint named once.
//! - this file: the hands from the config, checked, and the store of what
//!   users saved (poses, calibrations).

pub mod calibration;
pub mod pose;
pub mod saved;
pub mod state_file;

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::protocol::ids::parse_id_list;
pub use calibration::{Calibration, CalibrationError};
pub use pose::Pose;
use saved::Saved;
pub use saved::{DroppedCalibration, LoadNotes, SetAside};
pub use state_file::{StateFile, StateFileError};

/// `[[hand]]`: a named set of joints.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandConfig {
    pub name: String,
    pub joints: Vec<HandJoints>,
}

/// Joints of one bus in a hand: `{ bus = "l", ids = "1-8", names = [...] }`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandJoints {
    pub bus: String,
    pub ids: Ids,
    /// One name per id, in order; absent names are `<bus>_<id>`.
    #[serde(default)]
    pub names: Vec<String>,
}

/// An id, a list of ids, or a range spec such as `"1-8"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum Ids {
    One(u8),
    List(Vec<u8>),
    Spec(String),
}

/// One joint of a hand.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HandJoint {
    pub name: String,
    pub bus: String,
    pub id: u8,
}

/// A hand as the daemon uses it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Hand {
    pub name: String,
    pub joints: Vec<HandJoint>,
}

impl Hand {
    pub fn joint(&self, name: &str) -> Option<&HandJoint> {
        self.joints.iter().find(|j| j.name == name)
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum HandError {
    #[error("[[hand]] #{index}: a hand needs a name")]
    NoName { index: usize },
    #[error("hand `{0}` is named twice")]
    Twice(String),
    #[error("hand `{hand}`: no bus named `{bus}`")]
    UnknownBus { hand: String, bus: String },
    #[error("hand `{hand}`: ids of bus `{bus}`: {why}")]
    Ids {
        hand: String,
        bus: String,
        why: String,
    },
    #[error("hand `{hand}`: {names} names for {ids} ids on bus `{bus}`")]
    Names {
        hand: String,
        bus: String,
        names: usize,
        ids: usize,
    },
    #[error("hand `{hand}`: joint name `{name}` is used twice")]
    NameTwice { hand: String, name: String },
    #[error("hand `{hand}`: joint {id} of bus `{bus}` is listed twice")]
    JointTwice { hand: String, bus: String, id: u8 },
}

/// Checks the configured hands against the buses there are.
pub fn resolve(configs: &[HandConfig], buses: &[String]) -> Result<Vec<Hand>, HandError> {
    let mut hands: Vec<Hand> = Vec::new();
    for (index, c) in configs.iter().enumerate() {
        if c.name.trim().is_empty() {
            return Err(HandError::NoName { index });
        }
        if hands.iter().any(|h| h.name == c.name) {
            return Err(HandError::Twice(c.name.clone()));
        }
        let mut joints: Vec<HandJoint> = Vec::new();
        for part in &c.joints {
            joints_of(c, part, buses, &mut joints)?;
        }
        hands.push(Hand {
            name: c.name.clone(),
            joints,
        });
    }
    Ok(hands)
}

fn joints_of(
    c: &HandConfig,
    part: &HandJoints,
    buses: &[String],
    joints: &mut Vec<HandJoint>,
) -> Result<(), HandError> {
    if !buses.contains(&part.bus) {
        return Err(HandError::UnknownBus {
            hand: c.name.clone(),
            bus: part.bus.clone(),
        });
    }
    let ids = match &part.ids {
        Ids::One(id) => vec![*id],
        Ids::List(ids) => ids.clone(),
        Ids::Spec(spec) => parse_id_list(spec).map_err(|why| HandError::Ids {
            hand: c.name.clone(),
            bus: part.bus.clone(),
            why,
        })?,
    };
    if part.names.len() > ids.len() {
        return Err(HandError::Names {
            hand: c.name.clone(),
            bus: part.bus.clone(),
            names: part.names.len(),
            ids: ids.len(),
        });
    }
    for (k, id) in ids.iter().enumerate() {
        let name = part
            .names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("{}_{id}", part.bus));
        if joints.iter().any(|j| j.name == name) {
            return Err(HandError::NameTwice {
                hand: c.name.clone(),
                name,
            });
        }
        if joints.iter().any(|j| j.bus == part.bus && j.id == *id) {
            return Err(HandError::JointTwice {
                hand: c.name.clone(),
                bus: part.bus.clone(),
                id: *id,
            });
        }
        joints.push(HandJoint {
            name,
            bus: part.bus.clone(),
            id: *id,
        });
    }
    Ok(())
}

/// The hands, their poses and the joints' calibrations; saved to the state
/// file on every change when there is one (a std `Mutex`: never held across an `.await`).
#[derive(Debug)]
pub struct StateStore {
    hands: Vec<Hand>,
    file: Option<StateFile>,
    saved: Mutex<Saved>,
    notes: LoadNotes,
}

impl StateStore {
    /// The hands with the poses and calibrations the state file in
    /// `state_dir` holds (none without a `state_dir`: they then live until
    /// the daemon stops). Always `Ok`: a bad file is set aside or left
    /// alone and bad calibrations dropped, each logged and kept in
    /// [`Self::notes`], so that a bad file never keeps the daemon (and its
    /// e-stop) from starting.
    pub fn open(
        hands: Vec<Hand>,
        state_dir: Option<&std::path::Path>,
    ) -> Result<Self, StateFileError> {
        let file = state_dir.map(StateFile::new);
        let (saved, notes) = match &file {
            Some(f) => saved::load(f, std::time::SystemTime::now()),
            None => (Saved::default(), LoadNotes::default()),
        };
        Ok(Self {
            hands,
            file,
            saved: Mutex::new(saved),
            notes,
        })
    }

    /// What was wrong with the state file when the daemon started.
    pub fn notes(&self) -> &LoadNotes {
        &self.notes
    }

    fn lock(&self) -> MutexGuard<'_, Saved> {
        self.saved.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn hands(&self) -> &[Hand] {
        &self.hands
    }

    pub fn hand(&self, name: &str) -> Option<&Hand> {
        self.hands.iter().find(|h| h.name == name)
    }

    /// Where poses are kept, if anywhere but memory.
    pub fn state_path(&self) -> Option<std::path::PathBuf> {
        self.file.as_ref().map(StateFile::path)
    }

    pub fn poses(&self, hand: &str) -> BTreeMap<String, Pose> {
        self.lock().poses.get(hand).cloned().unwrap_or_default()
    }

    pub fn pose(&self, hand: &str, name: &str) -> Option<Pose> {
        self.lock()
            .poses
            .get(hand)
            .and_then(|p| p.get(name))
            .cloned()
    }

    /// Saves `pose` as `name` of `hand`; on a failed write nothing changes.
    pub fn put(&self, hand: &str, name: &str, pose: Pose) -> Result<(), StateFileError> {
        self.change(|s| {
            s.poses
                .entry(hand.to_string())
                .or_default()
                .insert(name.to_string(), pose);
        })
    }

    /// Forgets a pose; false when there was none.
    pub fn delete(&self, hand: &str, name: &str) -> Result<bool, StateFileError> {
        let mut existed = false;
        self.change(|s| {
            existed = s.poses.get_mut(hand).and_then(|p| p.remove(name)).is_some();
        })?;
        Ok(existed)
    }

    /// The calibration of joint `id` on `bus` (the identity if none).
    pub fn calibration(&self, bus: &str, id: u8) -> Calibration {
        self.lock()
            .calibration
            .get(bus)
            .and_then(|c| c.get(&id))
            .copied()
            .unwrap_or(Calibration::IDENTITY)
    }

    /// Every calibration saved: bus → id → calibration (what the tests
    /// look at to see that the identity leaves nothing behind).
    #[cfg(test)]
    pub fn calibrations(&self) -> BTreeMap<String, BTreeMap<u8, Calibration>> {
        self.lock().calibration.clone()
    }

    /// Saves the calibration of joint `id` on `bus` (the identity removes
    /// it); on a failed write nothing changes.
    pub fn set_calibration(
        &self,
        bus: &str,
        id: u8,
        cal: Calibration,
    ) -> Result<(), StateFileError> {
        self.change(|s| {
            if cal.is_identity() {
                if let Some(c) = s.calibration.get_mut(bus) {
                    c.remove(&id);
                    if c.is_empty() {
                        s.calibration.remove(bus);
                    }
                }
            } else {
                s.calibration
                    .entry(bus.to_string())
                    .or_default()
                    .insert(id, cal);
            }
        })
    }

    fn change(&self, edit: impl FnOnce(&mut Saved)) -> Result<(), StateFileError> {
        if let (Some(f), Some(reason)) = (&self.file, &self.notes.unusable) {
            return Err(StateFileError::Unusable {
                path: f.path(),
                reason: reason.clone(),
            });
        }
        let mut saved = self.lock();
        let mut next = saved.clone();
        next.version = 1;
        edit(&mut next);
        if let Some(f) = &self.file {
            f.save(&next)?;
        }
        *saved = next;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> Vec<HandConfig> {
        #[derive(Deserialize)]
        struct File {
            hand: Vec<HandConfig>,
        }
        toml::from_str::<File>(text).unwrap().hand
    }

    fn buses() -> Vec<String> {
        vec!["l".into(), "l2".into()]
    }

    #[test]
    fn a_hand_spans_buses_with_names_given_or_made() {
        let hands = resolve(
            &config(
                r#"
                [[hand]]
                name = "left"
                joints = [{ bus = "l", ids = "1-3", names = ["thumb", "index"] },
                          { bus = "l2", ids = [1] }]
                "#,
            ),
            &buses(),
        )
        .unwrap();
        let names: Vec<(&str, &str, u8)> = hands[0]
            .joints
            .iter()
            .map(|j| (j.name.as_str(), j.bus.as_str(), j.id))
            .collect();
        assert_eq!(
            names,
            vec![
                ("thumb", "l", 1),
                ("index", "l", 2),
                ("l_3", "l", 3),
                ("l2_1", "l2", 1)
            ]
        );
    }

    #[test]
    fn bad_hands_are_refused_with_the_reason() {
        let bad = |text: &str| resolve(&config(text), &buses()).unwrap_err();
        assert_eq!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "nope", ids = 1 }]"#),
            HandError::UnknownBus {
                hand: "x".into(),
                bus: "nope".into()
            }
        );
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = "1-2", names = ["a", "a"] }]"#),
            HandError::NameTwice { .. }
        ));
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = 1 }, { bus = "l", ids = "1", names = ["other"] }]"#),
            HandError::JointTwice { id: 1, .. }
        ));
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = "one" }]"#),
            HandError::Ids { .. }
        ));
    }

    #[test]
    fn poses_survive_a_new_store_on_the_same_state_dir() {
        let dir = std::env::temp_dir().join(format!("jointd-poses-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let hands = resolve(
            &config(
                r#"[[hand]]
name = "left"
joints = [{ bus = "l", ids = "1-2", names = ["thumb", "index"] }]"#,
            ),
            &buses(),
        )
        .unwrap();
        let store = StateStore::open(hands.clone(), Some(&dir)).unwrap();
        let fist = Pose::from([("thumb".into(), 40.0), ("index".into(), 80.0)]);
        store.put("left", "fist", fist.clone()).unwrap();
        store
            .put("left", "open", Pose::from([("thumb".into(), 0.0)]))
            .unwrap();
        assert!(store.delete("left", "open").unwrap());
        assert!(!store.delete("left", "open").unwrap());
        let again = StateStore::open(hands, Some(&dir)).unwrap();
        assert_eq!(again.pose("left", "fist"), Some(fist));
        assert_eq!(again.poses("left").len(), 1);
    }

    #[test]
    fn calibrations_survive_a_new_store_and_the_identity_removes_one() {
        let dir = std::env::temp_dir().join(format!("jointd-cal-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = StateStore::open(Vec::new(), Some(&dir)).unwrap();
        let cal = Calibration {
            offset_deg: 12.0,
            flip: true,
            range_deg: Some((-5.0, 80.0)),
            homed_at_ms: None,
        };
        store.set_calibration("l", 3, cal).unwrap();
        store.set_calibration("l", 4, cal).unwrap();
        store
            .set_calibration("l", 4, Calibration::IDENTITY)
            .unwrap();
        let again = StateStore::open(Vec::new(), Some(&dir)).unwrap();
        assert_eq!(again.calibration("l", 3), cal);
        assert_eq!(again.calibration("l", 4), Calibration::IDENTITY);
        assert_eq!(again.calibrations()["l"].len(), 1);
    }

    #[test]
    fn a_state_file_that_cannot_be_set_aside_is_never_written_over() {
        let dir = std::env::temp_dir().join(format!("jointd-stuck-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // A state_dir that is a file: unreadable, and no rename can move it.
        let not_a_dir = dir.join("file");
        std::fs::write(&not_a_dir, "keep").unwrap();
        let store = StateStore::open(Vec::new(), Some(&not_a_dir)).unwrap();
        assert!(store.notes().unusable.is_some());
        let err = store
            .put("left", "fist", Pose::from([("thumb".into(), 1.0)]))
            .unwrap_err();
        assert!(matches!(err, StateFileError::Unusable { .. }), "{err}");
        assert_eq!(store.pose("left", "fist"), None);
        assert_eq!(std::fs::read_to_string(&not_a_dir).unwrap(), "keep");
    }
}
