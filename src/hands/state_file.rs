//! The daemon's state file (`state_dir/state.json`): what users saved that
//! must survive a restart (poses). Written atomically: the new content goes
//! to a temporary file beside it, which is flushed to the disk, then renamed
//! over the old one, and the directory is flushed, so a kill or a power cut
//! at any point leaves either the old file or the new one, never a mix.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use serde::{de::DeserializeOwned, Serialize};
use thiserror::Error;

const FILE_NAME: &str = "state.json";
const TMP_NAME: &str = "state.json.tmp";

#[derive(Debug, Error)]
pub enum StateFileError {
    #[error("state file {path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("state file {path} is not valid JSON of the expected shape: {source}")]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// The state file in one directory.
#[derive(Debug, Clone)]
pub struct StateFile {
    dir: PathBuf,
}

/// Where a write may be cut short (a test's stand-in for a kill).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stage {
    /// Half the new content written to the temporary file.
    HalfWritten,
    /// The temporary file complete and flushed, not yet renamed.
    BeforeRename,
    /// Not cut short.
    Complete,
}

impl StateFile {
    /// The state file of `dir` (created on the first write if missing).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    pub fn path(&self) -> PathBuf {
        self.dir.join(FILE_NAME)
    }

    fn io(&self, source: io::Error) -> StateFileError {
        StateFileError::Io {
            path: self.path(),
            source,
        }
    }

    /// The saved state; `None` when there is no file yet.
    pub fn load<T: DeserializeOwned>(&self) -> Result<Option<T>, StateFileError> {
        let path = self.path();
        let text = match fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(self.io(e)),
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|source| StateFileError::Parse { path, source })
    }

    /// Replaces the saved state with `value`, atomically.
    pub fn save<T: Serialize>(&self, value: &T) -> Result<(), StateFileError> {
        self.save_until(value, Stage::Complete)
    }

    pub(crate) fn save_until<T: Serialize>(
        &self,
        value: &T,
        stop: Stage,
    ) -> Result<(), StateFileError> {
        let bytes = serde_json::to_vec_pretty(value).map_err(|e| self.io(io::Error::other(e)))?;
        fs::create_dir_all(&self.dir).map_err(|e| self.io(e))?;
        let tmp = self.dir.join(TMP_NAME);
        let mut file = File::create(&tmp).map_err(|e| self.io(e))?;
        if stop == Stage::HalfWritten {
            return file
                .write_all(&bytes[..bytes.len() / 2])
                .map_err(|e| self.io(e));
        }
        file.write_all(&bytes).map_err(|e| self.io(e))?;
        file.sync_all().map_err(|e| self.io(e))?;
        drop(file);
        if stop == Stage::BeforeRename {
            return Ok(());
        }
        fs::rename(&tmp, self.path()).map_err(|e| self.io(e))?;
        sync_dir(&self.dir).map_err(|e| self.io(e))
    }
}

/// Flushes a directory's entries (the rename) to the disk.
fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("jointd-state-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        d
    }

    fn state(v: f64) -> BTreeMap<String, f64> {
        BTreeMap::from([("thumb".to_string(), v), ("index".to_string(), -v)])
    }

    #[test]
    fn a_saved_state_is_loaded_back_and_no_file_is_none() {
        let f = StateFile::new(dir("roundtrip"));
        assert_eq!(f.load::<BTreeMap<String, f64>>().unwrap(), None);
        f.save(&state(1.5)).unwrap();
        assert_eq!(f.load().unwrap(), Some(state(1.5)));
        f.save(&state(2.5)).unwrap();
        assert_eq!(f.load().unwrap(), Some(state(2.5)));
    }

    #[test]
    fn a_write_cut_short_at_any_stage_leaves_the_old_file_whole() {
        for stage in [Stage::HalfWritten, Stage::BeforeRename] {
            let f = StateFile::new(dir(&format!("{stage:?}")));
            f.save(&state(1.0)).unwrap();
            f.save_until(&state(9.0), stage).unwrap();
            assert_eq!(f.load().unwrap(), Some(state(1.0)), "{stage:?}");
            // The next write replaces the leftover temporary file.
            f.save(&state(3.0)).unwrap();
            assert_eq!(f.load().unwrap(), Some(state(3.0)), "{stage:?}");
        }
    }

    #[test]
    fn a_file_that_is_not_the_state_says_so_with_its_path() {
        let d = dir("garbage");
        fs::create_dir_all(&d).unwrap();
        fs::write(d.join(FILE_NAME), "{not json").unwrap();
        let err = StateFile::new(&d)
            .load::<BTreeMap<String, f64>>()
            .unwrap_err();
        assert!(err.to_string().contains("state.json"), "{err}");
    }
}
