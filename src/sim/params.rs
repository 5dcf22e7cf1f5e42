//! A device's parameters (the RAM copy the firmware runs on and the flash
//! copy it boots from) and the optional JSON state file that keeps flash
//! across simulator restarts.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::protocol::params::{self, index, ParamRow};
use crate::protocol::{BaudLevel, ConfigParam, InfoBlock};

use super::error::SimError;

/// INFO_04's parameter version: not a config index, what the captured module reports.
pub(crate) const PARAM_VER: u8 = 3;
/// Where INFO_04 carries the parameter version.
const PARAM_VER_AT: usize = 2;
/// Config indices are below this (the table's tests keep it so).
const SLOTS: usize = 64;

/// The key names of a version 1 state file, which named each saved
/// parameter by hand instead of by its table row: such a flash image loads.
const LEGACY_KEYS: [(&str, u8); 11] = [
    ("max_cur", index::MAX_CUR),
    ("protect_limit", index::PROTECT_CUR_LIMIT),
    ("protect_lv1", index::PROTECT_CUR_LV1),
    ("lv1_delay_ms", index::CUR_LV1_DELAY),
    ("recv_cur", index::RECV_CUR),
    ("recv_win_ms", index::CUR_RECV_WIN),
    ("cold_time", index::COLD_TIME),
    ("plus_time", index::PLUS_TIME),
    ("drv_ot", index::DRV_OT),
    ("spd_limit", index::SPD_LIMIT),
    ("baud_level", index::BAUD_RATE),
];

/// Every setting of the parameter table (its RAM rows), raw as the wire
/// carries it, by config index. Defaults, storage and the INFO bytes that
/// report them all come from the table: a new row is stored and reported
/// with no change here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Params {
    raw: [u16; SLOTS],
    pub param_ver: u8,
}

impl Params {
    /// Factory parameters (the table's defaults), talking at `baud`.
    pub fn factory(baud: BaudLevel) -> Self {
        let mut p = Self {
            raw: [0; SLOTS],
            param_ver: PARAM_VER,
        };
        for row in params::settings() {
            p.set(row.index, row.default);
        }
        p.set(index::BAUD_RATE, baud as u16);
        p
    }

    /// The raw value of a setting (0 for an index that is not one).
    pub fn raw(&self, index: u8) -> u16 {
        self.raw.get(usize::from(index)).copied().unwrap_or(0)
    }

    /// A setting in physical units, through its row's scale (amps, ms, …).
    pub fn physical(&self, index: u8) -> f64 {
        params::by_index(index).map_or(0.0, |row| row.physical(self.raw(index)))
    }

    /// Sets a setting's raw value directly (a device's own factory values, like its serial).
    pub(crate) fn set_raw(&mut self, index: u8, raw: u16) {
        self.set(index, raw);
    }

    fn set(&mut self, index: u8, raw: u16) {
        if let Some(slot) = self.raw.get_mut(usize::from(index)) {
            *slot = raw;
        }
    }

    /// The baud these parameters select (a corrupt level falls back to the factory one).
    pub fn baud(&self) -> u32 {
        u8::try_from(self.raw(index::BAUD_RATE))
            .ok()
            .and_then(BaudLevel::from_raw)
            .unwrap_or(BaudLevel::B230400)
            .baud()
    }

    /// Stores a write of a setting. Returns false for params that are not
    /// plain values (commands like SET_ID, reads), which the device handles.
    pub fn apply(&mut self, p: &ConfigParam) -> bool {
        let (index, value) = p.index_value();
        let setting = params::by_index(index).is_some_and(ParamRow::is_setting);
        if setting {
            self.set(index, value);
        }
        setting
    }

    /// The data bytes of INFO_03..06: every setting at its row's read-back
    /// field (INFO_06's rev 2.0.8 tail stays zero here: its offsets are
    /// unpublished; a rev 2.0.8 device adds the simulator's own layout).
    pub fn block(&self, block: InfoBlock) -> [u8; 8] {
        let mut data = [0u8; 8];
        if block == InfoBlock::Info04 {
            data[PARAM_VER_AT] = self.param_ver;
        }
        for (row, field) in params::fields_of(block) {
            field.write(&mut data, self.raw(row.index));
        }
        data
    }
}

impl Serialize for Params {
    /// `{"pos_kp": 4095, …, "param_ver": 3}`: settings by their table key.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map: BTreeMap<&str, u16> = params::settings()
            .map(|r| (r.key, self.raw(r.index)))
            .collect();
        map.insert("param_ver", self.param_ver.into());
        map.serialize(s)
    }
}

impl<'de> Deserialize<'de> for Params {
    /// Table keys or the version-1 names; a missing setting gets its factory value.
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let map = BTreeMap::<String, u16>::deserialize(d)?;
        let mut p = Self::factory(BaudLevel::B230400);
        for (key, value) in map {
            if key == "param_ver" {
                p.param_ver = u8::try_from(value).unwrap_or(PARAM_VER);
            } else if let Some(row) = params::by_key(&key).filter(|r| r.is_setting()) {
                p.set(row.index, value);
            } else if let Some((_, index)) = LEGACY_KEYS.iter().find(|(k, _)| *k == key) {
                p.set(*index, value);
            }
        }
        Ok(p)
    }
}

/// What one device keeps in flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct FlashImage {
    pub id: u8,
    pub params: Params,
}

/// The state file: one flash image per bus slot.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
struct StateFile {
    version: u32,
    devices: Vec<FlashImage>,
}

const STATE_VERSION: u32 = 1;

/// Flash of every device on the bus, optionally backed by a file.
#[derive(Debug, Clone)]
pub(crate) struct FlashStore {
    path: Option<PathBuf>,
}

impl FlashStore {
    pub(crate) fn new(path: Option<PathBuf>) -> Self {
        Self { path }
    }

    /// Flash images saved by an earlier run, by slot (missing file: none).
    pub(crate) fn load(&self) -> Result<Vec<FlashImage>, SimError> {
        let Some(path) = &self.path else {
            return Ok(Vec::new());
        };
        let text = match fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(state_err(path, e)),
        };
        let state: StateFile = serde_json::from_str(&text).map_err(|e| state_err(path, e))?;
        Ok(state.devices)
    }

    /// Writes all images (atomically: temp file, then rename).
    pub(crate) fn save(&self, images: &[FlashImage]) -> Result<(), SimError> {
        let Some(path) = &self.path else {
            return Ok(());
        };
        let state = StateFile {
            version: STATE_VERSION,
            devices: images.to_vec(),
        };
        let text = serde_json::to_string_pretty(&state).map_err(|e| state_err(path, e))?;
        let tmp = path.with_extension("tmp");
        fs::write(&tmp, text).map_err(|e| state_err(&tmp, e))?;
        fs::rename(&tmp, path).map_err(|e| state_err(path, e))
    }
}

fn state_err(path: &Path, why: impl std::fmt::Display) -> SimError {
    SimError::StateFile {
        path: path.to_path_buf(),
        why: why.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factory_blocks_match_the_captured_device() {
        let p = Params::factory(BaudLevel::B230400);
        assert_eq!(
            p.block(InfoBlock::Info03),
            [0xFF, 0x0F, 0xFF, 0x0F, 0xFF, 0x03, 0x51, 0x00]
        );
        assert_eq!(
            p.block(InfoBlock::Info04),
            [1, 1, 3, 0, 0x10, 0x11, 0x69, 0x03]
        );
        assert_eq!(
            p.block(InfoBlock::Info05),
            [0x60, 0x0B, 0x58, 0x02, 0x46, 0x02, 0x90, 0x01]
        );
        assert_eq!(p.block(InfoBlock::Info06), [20, 4, 0, 0, 0, 0, 0, 0]);
    }

    #[test]
    fn state_file_round_trips() {
        let dir = std::env::temp_dir().join(format!("jointd-params-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let store = FlashStore::new(Some(dir.join("state.json")));
        assert!(store.load().unwrap().is_empty());
        let mut params = Params::factory(BaudLevel::B500000);
        params.apply(&ConfigParam::MaxCur(1234));
        let images = vec![FlashImage { id: 7, params }];
        store.save(&images).unwrap();
        assert_eq!(store.load().unwrap(), images);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn version_1_state_files_still_load() {
        let old = r#"{"pos_kp":1,"pos_kd":2,"spd_kp":3,"spd_ki":4,"lpf_level":5,"baud_level":0,
            "param_ver":3,"max_cur":6,"protect_limit":7,"protect_lv1":8,"lv1_delay_ms":9,
            "recv_cur":10,"recv_win_ms":11,"cold_time":12,"plus_time":13,"drv_ot":80,
            "spd_limit":14,"sn":15}"#;
        let p: Params = serde_json::from_str(old).unwrap();
        assert_eq!(p.raw(index::MAX_CUR), 6);
        assert_eq!(p.raw(index::CUR_RECV_WIN), 11);
        assert_eq!(p.raw(index::DRV_OT), 80);
        assert_eq!(p.baud(), 500_000);
        let again: Params = serde_json::from_value(serde_json::to_value(p).unwrap()).unwrap();
        assert_eq!(again, p);
    }

    #[test]
    fn every_setting_of_the_table_is_stored_and_survives_the_state_file() {
        let mut p = Params::factory(BaudLevel::B500000);
        for row in params::settings() {
            assert_eq!(
                p.raw(row.index),
                if row.index == index::BAUD_RATE {
                    0
                } else {
                    row.default
                }
            );
            let value = row.range.1;
            let write = ConfigParam::from_index_value(row.index, value).unwrap();
            assert!(p.apply(&write), "{}", row.name);
            assert_eq!(p.raw(row.index), value, "{}", row.name);
        }
        let again: Params = serde_json::from_value(serde_json::to_value(p).unwrap()).unwrap();
        assert_eq!(again, p);
    }
}
