//! The store of what users saved: the hands' poses and the joints'
//! calibrations, read from the state file when the daemon starts (checked,
//! see [`super::saved`]) and written back whole on every change.

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard};

use super::calibration::Calibration;
use super::hand::Hand;
use super::pose::Pose;
use super::saved::{self, LoadNotes, Saved};
use super::state_file::{StateFile, StateFileError};

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
    use crate::hands::{resolve, HandConfig};
    use crate::test_dir::TestDir;

    fn config(text: &str) -> Vec<HandConfig> {
        #[derive(serde::Deserialize)]
        struct File {
            hand: Vec<HandConfig>,
        }
        toml::from_str::<File>(text).unwrap().hand
    }

    #[test]
    fn poses_survive_a_new_store_on_the_same_state_dir() {
        let dir = TestDir::new("poses");
        let hands = resolve(
            &config(
                r#"[[hand]]
name = "left"
joints = [{ bus = "l", ids = "1-2", names = ["thumb", "index"] }]"#,
            ),
            &["l".to_string()],
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
        let dir = TestDir::new("cal");
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
        let dir = TestDir::new("stuck");
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
