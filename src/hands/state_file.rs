//! The daemon's state file (`state_dir/state.json`): what users saved that
//! must survive a restart (poses, calibrations). Written atomically: the new
//! content goes to a temporary file beside it, which is flushed to the disk,
//! then renamed over the old one, and the directory is flushed, so a kill or
//! a power cut at any point leaves either the old file or the new one, never
//! a mix. A file that cannot be used is set aside (renamed beside, never
//! deleted) so the daemon can start without it and the user can look at it.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

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
    /// Writing would destroy a file the daemon could neither read nor set aside.
    #[error("state file {path} could not be used or set aside when the daemon started ({reason}); it is left as it is and nothing is saved")]
    Unusable { path: PathBuf, reason: String },
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
        let bytes = match fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(self.io(e)),
        };
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|source| StateFileError::Parse { path, source })
    }

    /// Renames the file to `state.json.bad-<UTC time>` beside it (a free
    /// name: a number is added if that one is taken) and flushes the
    /// directory; the new path. The next save writes a whole new file.
    pub fn set_aside(&self, now: SystemTime) -> io::Result<PathBuf> {
        let stamp = utc_stamp(now);
        let mut to = self.dir.join(format!("{FILE_NAME}.bad-{stamp}"));
        let mut n = 1;
        while to.symlink_metadata().is_ok() {
            n += 1;
            to = self.dir.join(format!("{FILE_NAME}.bad-{stamp}-{n}"));
        }
        fs::rename(self.path(), &to)?;
        sync_dir(&self.dir)?;
        Ok(to)
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

/// `20250102T030405Z`: a UTC time that sorts as text and is safe in a file
/// name on every file system (no `:`).
fn utc_stamp(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days);
    let (hh, mm, ss) = (rem / 3600, rem / 60 % 60, rem % 60);
    format!("{y:04}{m:02}{d:02}T{hh:02}{mm:02}{ss:02}Z")
}

/// The Gregorian date `days` after 1970-01-01 (H. Hinnant's algorithm, on
/// 400-year eras of 146097 days).
fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468; // days from 0000-03-01
    let era = z / 146_097;
    let doe = z % 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::test_dir::TestDir;

    fn dir(name: &str) -> TestDir {
        TestDir::new(&format!("state-{name}"))
    }

    fn state(v: f64) -> BTreeMap<String, f64> {
        BTreeMap::from([("thumb".to_string(), v), ("index".to_string(), -v)])
    }

    #[test]
    fn a_saved_state_is_loaded_back_and_no_file_is_none() {
        let d = dir("roundtrip");
        let f = StateFile::new(d.path());
        assert_eq!(f.load::<BTreeMap<String, f64>>().unwrap(), None);
        f.save(&state(1.5)).unwrap();
        assert_eq!(f.load().unwrap(), Some(state(1.5)));
        f.save(&state(2.5)).unwrap();
        assert_eq!(f.load().unwrap(), Some(state(2.5)));
    }

    #[test]
    fn a_write_cut_short_at_any_stage_leaves_the_old_file_whole() {
        for stage in [Stage::HalfWritten, Stage::BeforeRename] {
            let d = dir(&format!("{stage:?}"));
            let f = StateFile::new(d.path());
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
        fs::write(d.join(FILE_NAME), "{not json").unwrap();
        let err = StateFile::new(d.path())
            .load::<BTreeMap<String, f64>>()
            .unwrap_err();
        assert!(err.to_string().contains("state.json"), "{err}");
    }

    #[test]
    fn a_file_set_aside_keeps_its_content_under_a_free_dated_name() {
        let d = dir("aside");
        let f = StateFile::new(d.path());
        let at = UNIX_EPOCH + std::time::Duration::from_secs(1_735_787_045);
        fs::write(f.path(), "first").unwrap();
        let first = f.set_aside(at).unwrap();
        assert_eq!(first, d.join("state.json.bad-20250102T030405Z"));
        fs::write(f.path(), "second").unwrap();
        let second = f.set_aside(at).unwrap();
        assert_eq!(second, d.join("state.json.bad-20250102T030405Z-2"));
        assert_eq!(fs::read_to_string(first).unwrap(), "first");
        assert_eq!(fs::read_to_string(second).unwrap(), "second");
        assert!(!f.path().exists());
    }

    #[test]
    fn utc_stamps_match_known_dates() {
        let at = |s| utc_stamp(UNIX_EPOCH + std::time::Duration::from_secs(s));
        assert_eq!(at(0), "19700101T000000Z");
        assert_eq!(at(951_782_400), "20000229T000000Z");
        assert_eq!(at(4_102_444_799), "20991231T235959Z");
    }
}
