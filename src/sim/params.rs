//! A device's parameters (the RAM copy the firmware runs on and the flash
//! copy it boots from) and the optional JSON state file that keeps flash
//! across simulator restarts.

use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::protocol::reply::{Gains, Info04, Info05, Info06};
use crate::protocol::{BaudLevel, ConfigParam};

use super::config::SimError;

/// Factory values, from the INFO_03/04/05 a real module reported (vectors.json).
pub mod factory {
    pub const POS_KP: u16 = 4095;
    pub const POS_KD: u16 = 4095;
    pub const SPD_KP: u16 = 1023;
    pub const SPD_KI: u16 = 81;
    pub const LPF_LEVEL: u8 = 1;
    pub const PARAM_VER: u8 = 3;
    /// 0.75 A.
    pub const MAX_CUR: u16 = 4368;
    /// 0.15 A.
    pub const PROTECT_LIMIT: u16 = 873;
    /// 0.5 A.
    pub const PROTECT_LV1: u16 = 2912;
    pub const LV1_DELAY_MS: u16 = 600;
    /// 0.1 A.
    pub const RECV_CUR: u16 = 582;
    pub const RECV_WIN_MS: u16 = 400;
    /// × 25 ms.
    pub const COLD_TIME: u8 = 20;
    pub const PLUS_TIME: u8 = 4;
    /// °C.
    pub const DRV_OT: u8 = 90;
    /// Q15: no limit below the base speed.
    pub const SPD_LIMIT: u16 = 32767;
}

/// Every writable parameter, raw as the wire carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Params {
    pub pos_kp: u16,
    pub pos_kd: u16,
    pub spd_kp: u16,
    pub spd_ki: u16,
    pub lpf_level: u8,
    pub baud_level: u8,
    pub param_ver: u8,
    pub max_cur: u16,
    pub protect_limit: u16,
    pub protect_lv1: u16,
    pub lv1_delay_ms: u16,
    pub recv_cur: u16,
    pub recv_win_ms: u16,
    pub cold_time: u8,
    pub plus_time: u8,
    pub drv_ot: u8,
    pub spd_limit: u16,
    pub sn: u16,
}

impl Params {
    /// Factory parameters, talking at `baud`.
    pub fn factory(baud: BaudLevel) -> Self {
        use factory::*;
        Self {
            pos_kp: POS_KP,
            pos_kd: POS_KD,
            spd_kp: SPD_KP,
            spd_ki: SPD_KI,
            lpf_level: LPF_LEVEL,
            baud_level: baud as u8,
            param_ver: PARAM_VER,
            max_cur: MAX_CUR,
            protect_limit: PROTECT_LIMIT,
            protect_lv1: PROTECT_LV1,
            lv1_delay_ms: LV1_DELAY_MS,
            recv_cur: RECV_CUR,
            recv_win_ms: RECV_WIN_MS,
            cold_time: COLD_TIME,
            plus_time: PLUS_TIME,
            drv_ot: DRV_OT,
            spd_limit: SPD_LIMIT,
            sn: 0,
        }
    }

    /// The baud these parameters select (a corrupt level falls back to the factory one).
    pub fn baud(&self) -> u32 {
        BaudLevel::from_raw(self.baud_level)
            .unwrap_or(BaudLevel::B230400)
            .baud()
    }

    /// Stores a RAM parameter write. Returns false for params that are not
    /// plain values (commands like SET_ID, reads), which the device handles.
    pub fn apply(&mut self, p: &ConfigParam) -> bool {
        match *p {
            ConfigParam::PosKp(v) => self.pos_kp = v,
            ConfigParam::PosKd(v) => self.pos_kd = v,
            ConfigParam::SpdKp(v) => self.spd_kp = v,
            ConfigParam::SpdKi(v) => self.spd_ki = v,
            ConfigParam::PosLpf(v) => self.lpf_level = v,
            ConfigParam::MaxCur(v) => self.max_cur = v,
            ConfigParam::ProtectCurLimit(v) => self.protect_limit = v,
            ConfigParam::ProtectCurLv1(v) => self.protect_lv1 = v,
            ConfigParam::CurLv1DelayMs(v) => self.lv1_delay_ms = v,
            ConfigParam::RecvCur(v) => self.recv_cur = v,
            ConfigParam::CurRecvWinMs(v) => self.recv_win_ms = v,
            ConfigParam::ColdTime(v) => self.cold_time = v,
            ConfigParam::PlusTime(v) => self.plus_time = v,
            ConfigParam::DrvOtC(v) => self.drv_ot = v,
            ConfigParam::SpdLimit(v) => self.spd_limit = v,
            ConfigParam::Sn(v) => self.sn = v,
            _ => return false,
        }
        true
    }

    pub fn gains(&self) -> Gains {
        Gains {
            pos_kp: self.pos_kp,
            pos_kd: self.pos_kd,
            spd_kp: self.spd_kp,
            spd_ki: self.spd_ki,
        }
    }

    pub fn info04(&self) -> Info04 {
        Info04 {
            lpf_level: self.lpf_level,
            baud_level: self.baud_level,
            param_ver: self.param_ver,
            reserved: 0,
            max_current: self.max_cur,
            protect_limit: self.protect_limit,
        }
    }

    pub fn info05(&self) -> Info05 {
        Info05 {
            protect_cur_lv1: self.protect_lv1,
            protect_delay_lv1_ms: self.lv1_delay_ms,
            recv_cur: self.recv_cur,
            recover_delay_ms: self.recv_win_ms,
        }
    }

    /// INFO_06: burst timing; the rev 2.0.8 tail's offsets are unpublished, so
    /// the simulator sends zeros there rather than invent a layout.
    pub fn info06(&self) -> Info06 {
        Info06 {
            cold_dt: self.cold_time,
            plus_t: self.plus_time,
            extra: [0; 6],
        }
    }
}

/// What one device keeps in flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FlashImage {
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
pub struct FlashStore {
    path: Option<PathBuf>,
}

impl FlashStore {
    pub fn new(path: Option<PathBuf>) -> Self {
        Self { path }
    }

    /// Flash images saved by an earlier run, by slot (missing file: none).
    pub fn load(&self) -> Result<Vec<FlashImage>, SimError> {
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
    pub fn save(&self, images: &[FlashImage]) -> Result<(), SimError> {
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
            p.gains().to_bytes(),
            [0xFF, 0x0F, 0xFF, 0x0F, 0xFF, 0x03, 0x51, 0x00]
        );
        assert_eq!(p.info04().to_bytes(), [1, 1, 3, 0, 0x10, 0x11, 0x69, 0x03]);
        assert_eq!(
            p.info05().to_bytes(),
            [0x60, 0x0B, 0x58, 0x02, 0x46, 0x02, 0x90, 0x01]
        );
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
}
