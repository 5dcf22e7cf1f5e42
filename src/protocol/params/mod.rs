//! The parameter table: one row per config index of SPEC §4.3 (the reads of
//! the INFO blocks included), with everything the program knows about it.
//!
//! The codec names indices and checks values with it, `frame_json` shows
//! physical values with it, the REST config surface and its OpenAPI schema
//! list writable parameters from it, the bus confirms writes the way a row
//! says, the simulator stores, defaults and reports parameters from it, and
//! the dashboard fetches it (`GET /api/v1/params`). Servo stacks keep one
//! control table for the same reason: a fact written twice drifts.
//!
//! # Adding an index
//! 1. Add a [`ParamRow`] to [`PARAMS`] (and, for code that must name it, a
//!    constant in [`index`]). Fill every field from SPEC: raw type, scale,
//!    range, reply kind, read-back field, storage, revision, description.
//!    Set `api: true` if `GET/PATCH …/config` should offer it.
//! 2. Run `cargo test --lib protocol::params`: the consistency tests check
//!    the new row (unique index and names, range within its raw type, scale
//!    round-trips, read-back field inside its block). `tests` adds a
//!    fictitious row in test builds and shows it decoded and shown as JSON;
//!    the crate's `params_reach` tests show the same row offered by the REST
//!    schema, confirmed by the bus and stored by the simulator, with no other
//!    code changed.
//! 3. Regenerate `openapi/openapi.json` if the row is `api: true`
//!    (`JOINTD_BLESS_OPENAPI=1 cargo test --test api_openapi`).
//!
//! A typed [`ConfigParam`](super::ConfigParam) variant is only needed when
//! code acts on the value (the simulator's physics, the bus's id change);
//! without one the index travels as `ConfigParam::Other` and every generic
//! path above still works.

mod row;
mod scale;

pub use row::{
    Access, Field, Guard, ParamRow, RawType, ReplyKind, Revision, Storage, UnknownRevision,
};
pub use scale::Scale;

use super::values::{BaudLevel, CtrlMode, InfoBlock};

/// Index constants of SPEC §4.3, named as the vendor names them.
pub mod index {
    pub const REBOOT: u8 = 0;
    pub const INFO_01_R: u8 = 1;
    pub const INFO_02_R: u8 = 2;
    pub const UPDATE_FIN_ZERO: u8 = 3;
    pub const SET_ID: u8 = 4;
    pub const UPDATE_ENC_ZERO: u8 = 5;
    pub const COMM_SILENT: u8 = 6;
    pub const CTRL_MODE_SW: u8 = 7;
    pub const SET_POS_KP: u8 = 8;
    pub const SET_POS_KD: u8 = 9;
    pub const SET_SPD_KP: u8 = 10;
    pub const SET_SPD_KI: u8 = 11;
    pub const INFO_03_R: u8 = 12;
    pub const WRITE_FLASH: u8 = 13;
    pub const READ_FLASH: u8 = 14;
    pub const BAUD_RATE: u8 = 15;
    pub const POS_LPF_LV: u8 = 16;
    pub const INFO_04_R: u8 = 17;
    pub const MAX_CUR: u8 = 18;
    pub const PROTECT_CUR_LIMIT: u8 = 19;
    pub const PROTECT_CUR_LV1: u8 = 20;
    pub const CUR_LV1_DELAY: u8 = 21;
    pub const RECV_CUR: u8 = 22;
    pub const CUR_RECV_WIN: u8 = 23;
    pub const INFO_05_R: u8 = 24;
    pub const INFO_06_R: u8 = 25;
    pub const COLD_TIME: u8 = 26;
    pub const PLUS_TIME: u8 = 27;
    pub const DRV_OT: u8 = 28;
    pub const SPD_LIMIT: u8 = 30;
    pub const SN: u8 = 31;
    pub const INFO_07_R: u8 = 32;
}

const fn f(block: InfoBlock, at: usize, width: RawType) -> Option<Field> {
    Some(Field { block, at, width })
}

/// A read of an INFO block.
const fn read(
    index: u8,
    name: &'static str,
    key: &'static str,
    since: Revision,
    doc: &'static str,
) -> ParamRow {
    ParamRow {
        index,
        name,
        key,
        access: Access::Read,
        raw: RawType::None,
        scale: Scale::Plain,
        range: (0, 0),
        reply: ReplyKind::Info,
        read_back: None,
        storage: Storage::None,
        guard: Guard::None,
        api: false,
        default: 0,
        since,
        doc,
    }
}

/// An action without a value.
const fn action(
    index: u8,
    name: &'static str,
    key: &'static str,
    reply: ReplyKind,
    guard: Guard,
    doc: &'static str,
) -> ParamRow {
    ParamRow {
        index,
        name,
        key,
        access: Access::Write,
        raw: RawType::None,
        scale: Scale::Plain,
        range: (0, 0),
        reply,
        read_back: None,
        storage: Storage::None,
        guard,
        api: false,
        default: 0,
        since: Revision::V2_0_1,
        doc,
    }
}

/// A RAM setting offered by the REST config surface, read back from `read_back`.
#[allow(clippy::too_many_arguments)]
const fn setting(
    index: u8,
    name: &'static str,
    key: &'static str,
    raw: RawType,
    scale: Scale,
    range: (u16, u16),
    read_back: Option<Field>,
    default: u16,
    doc: &'static str,
) -> ParamRow {
    ParamRow {
        index,
        name,
        key,
        access: Access::Write,
        raw,
        scale,
        range,
        reply: ReplyKind::None,
        read_back,
        storage: Storage::Ram,
        guard: Guard::None,
        api: true,
        default,
        since: Revision::V2_0_1,
        doc,
    }
}

/// A rev 2.0.8 setting: offered by the REST surface to devices that speak
/// rev 2.0.8 only, write-only (INFO_06's offsets for them are unpublished,
/// so no read-back confirms a write); the daemon never depends on them
/// (SPEC: "decode them, never depend on them").
const fn extension(
    index: u8,
    name: &'static str,
    key: &'static str,
    raw: RawType,
    scale: Scale,
    default: u16,
    doc: &'static str,
) -> ParamRow {
    ParamRow {
        index,
        name,
        key,
        access: Access::Write,
        raw,
        scale,
        range: (0, raw.max()),
        reply: ReplyKind::None,
        read_back: None,
        storage: Storage::Ram,
        guard: Guard::None,
        api: true,
        default,
        since: Revision::V2_0_8,
        doc,
    }
}

use index as i;
use InfoBlock as B;
use RawType::{U16, U8};

const Q15_RAW: (u16, u16) = (0, 32767);

/// Every row SPEC §4.3 documents, by index.
pub const PARAMS: &[ParamRow] = &[
    ParamRow {
        raw: U16,
        range: (0, u16::MAX),
        ..action(i::REBOOT, "REBOOT", "reboot", ReplyKind::None, Guard::None,
            "Reset request (only in the vendor's code list); the value is sent as given.")
    },
    read(i::INFO_01_R, "INFO_01_R", "info_01", Revision::V2_0_1, "Read INFO_01: state, fault, firmware, temperature, angle, bus voltage."),
    read(i::INFO_02_R, "INFO_02_R", "info_02", Revision::V2_0_1, "Read INFO_02: D/Q current, rotor speed, angle."),
    action(i::UPDATE_FIN_ZERO, "UPDATE_FIN_ZERO", "update_fin_zero", ReplyKind::None, Guard::None,
        "Set the output-angle zero at the current position."),
    ParamRow {
        raw: U16,
        scale: Scale::DeviceIdQ7,
        range: (1 << 7, 159 << 7),
        storage: Storage::Flash,
        ..action(i::SET_ID, "SET_ID", "new_id", ReplyKind::Res,
            Guard::Routed("an id change must go through set_id (the registry follows it)"),
            "Change the device id (sent as new_id << 7); stored to flash at once, RES comes from the new id.")
    },
    action(i::UPDATE_ENC_ZERO, "UPDATE_ENC_ZERO", "update_enc_zero", ReplyKind::Res,
        Guard::Dangerous("UPDATE_ENC_ZERO recalibrates the rotor encoder: not offered"),
        "Rotor encoder zero calibration: dangerous (RES since rev 2.0.8)."),
    ParamRow {
        raw: U16,
        range: (0, u16::MAX),
        storage: Storage::Volatile,
        ..action(i::COMM_SILENT, "COMM_SILENT", "comm_silent", ReplyKind::None,
            Guard::Dangerous("COMM_SILENT makes the device stop answering: not offered"),
            "The device stops answering anything but this command: dangerous.")
    },
    ParamRow {
        raw: U8,
        scale: Scale::CtrlMode,
        range: (0, 3),
        storage: Storage::Volatile,
        default: CtrlMode::Position as u16,
        ..action(i::CTRL_MODE_SW, "CTRL_MODE_SW", "mode", ReplyKind::None, Guard::None,
            "Control mode: 0 none, 1 speed, 2 position, 3 current (rev 2.0.8); not saved.")
    },
    setting(i::SET_POS_KP, "SET_POS_KP", "pos_kp", U16, Scale::GainQ12, Q15_RAW,
        f(B::Info03, 0, U16), 4095, "Position loop KP"),
    setting(i::SET_POS_KD, "SET_POS_KD", "pos_kd", U16, Scale::GainQ12, Q15_RAW,
        f(B::Info03, 2, U16), 4095, "Position loop KD"),
    setting(i::SET_SPD_KP, "SET_SPD_KP", "spd_kp", U16, Scale::GainQ12, Q15_RAW,
        f(B::Info03, 4, U16), 1023, "Speed loop KP"),
    setting(i::SET_SPD_KI, "SET_SPD_KI", "spd_ki", U16, Scale::GainQ15, Q15_RAW,
        f(B::Info03, 6, U16), 81, "Speed loop KI"),
    read(i::INFO_03_R, "INFO_03_R", "info_03", Revision::V2_0_1, "Read INFO_03: the four control gains."),
    ParamRow {
        raw: U8,
        range: (0, 255),
        ..action(i::WRITE_FLASH, "WRITE_FLASH", "write_flash", ReplyKind::Res, Guard::None,
            "Persist the RAM parameters; the key must be 0xA5.")
    },
    action(i::READ_FLASH, "READ_FLASH", "read_flash", ReplyKind::None, Guard::None,
        "Reload the parameters from flash (only in the vendor's code list)."),
    ParamRow {
        reply: ReplyKind::Res,
        guard: Guard::Routed("a baud change must go through set_baud (every device, then the port)"),
        api: false,
        ..setting(i::BAUD_RATE, "BUAD_RATE", "baud_level", U8, Scale::BaudLevel, (0, 4),
            f(B::Info04, 1, U8), BaudLevel::B230400 as u16,
            "Baud level (0 = 500000, 1 = 230400, 2 = 115200, 3 = 38400, 4 = 19200); the host must then switch its port")
    },
    setting(i::POS_LPF_LV, "POS_LPF_LV", "lpf_level", U8, Scale::Plain, (0, 5),
        f(B::Info04, 0, U8), 1, "Position smoothing level (higher = smoother)"),
    read(i::INFO_04_R, "INFO_04_R", "info_04", Revision::V2_0_1, "Read INFO_04: smoothing, baud level, parameter version, current limits."),
    setting(i::MAX_CUR, "MAX_CUR", "max_current_a", U16, Scale::CurrentQ15, Q15_RAW,
        f(B::Info04, 4, U16), 4368, "Maximum output current"),
    setting(i::PROTECT_CUR_LIMIT, "PROTECT_CUR_LIMIT", "protect_current_limit_a", U16, Scale::CurrentQ15, Q15_RAW,
        f(B::Info04, 6, U16), 873, "Current cap while protection is active"),
    setting(i::PROTECT_CUR_LV1, "PROTECT_CUR_LV1", "protect_current_lv1_a", U16, Scale::CurrentQ15, Q15_RAW,
        f(B::Info05, 0, U16), 2912, "Protection level-1 threshold"),
    setting(i::CUR_LV1_DELAY, "CUR_LV1_DELAY", "protect_delay_ms", U16, Scale::Millis, (0, 65000),
        f(B::Info05, 2, U16), 600, "Time above the threshold before protection engages"),
    setting(i::RECV_CUR, "RECV_CUR", "recover_current_a", U16, Scale::CurrentQ15, Q15_RAW,
        f(B::Info05, 4, U16), 582, "Recovery threshold"),
    setting(i::CUR_RECV_WIN, "CUR_RECV_WIN", "recover_window_ms", U16, Scale::Millis, (0, 65000),
        f(B::Info05, 6, U16), 400, "Time below the recovery threshold before protection releases"),
    read(i::INFO_05_R, "INFO_05_R", "info_05", Revision::V2_0_1, "Read INFO_05: current protection thresholds and delays."),
    read(i::INFO_06_R, "INFO_06_R", "info_06", Revision::V2_0_1, "Read INFO_06: burst timing (rev 2.0.8 adds unpublished bytes)."),
    setting(i::COLD_TIME, "COLD_TIME", "burst_cold_ms", U8, Scale::Burst25Ms, (0, 255),
        f(B::Info06, 0, U8), 20, "Burst cool-down"),
    setting(i::PLUS_TIME, "PLUS_TIME", "burst_plus_ms", U8, Scale::Burst25Ms, (0, 255),
        f(B::Info06, 1, U8), 4, "Burst duration"),
    extension(i::DRV_OT, "DRV_OT", "drv_ot_c", U8, Scale::Celsius, 90,
        "Driver over-temperature threshold (recovers 10 °C below)."),
    // Factory limit: the vendor's recommended maximum rotor speed, 20000 rpm
    // (SPEC §4.1, `13106`), not the 50000 rpm base: a host that relies on the
    // limit (speed reference 0) then moves no faster than the vendor advises.
    ParamRow {
        range: Q15_RAW,
        ..extension(i::SPD_LIMIT, "SPD_LIMIT", "spd_limit_rpm", U16, Scale::SpeedQ15, 13106,
            "Rotor speed limit (Q15); in position mode a zero speed reference moves at it.")
    },
    extension(i::SN, "SN", "sn", U16, Scale::Plain, 0, "Serial number (undocumented layout)."),
    read(i::INFO_07_R, "INFO_07_R", "info_07", Revision::V2_0_8, "Read INFO_07: serial number bytes (layout unpublished)."),
    #[cfg(test)]
    tests::FICTITIOUS,
];

/// The row of a config index.
pub fn by_index(index: u8) -> Option<&'static ParamRow> {
    PARAMS.iter().find(|r| r.index == index)
}

/// The row of a vendor name, with or without `CONFIG_`, any case.
pub fn by_name(name: &str) -> Option<&'static ParamRow> {
    let bare = name.strip_prefix("CONFIG_").unwrap_or(name);
    PARAMS.iter().find(|r| r.name.eq_ignore_ascii_case(bare))
}

/// The row of a snake_case key (a REST field name).
pub fn by_key(key: &str) -> Option<&'static ParamRow> {
    PARAMS.iter().find(|r| r.key == key)
}

/// The vendor name of an index without `CONFIG_`, `"UNKNOWN"` if no row has it.
pub fn name_of(index: u8) -> &'static str {
    by_index(index).map_or("UNKNOWN", |r| r.name)
}

/// The rows the REST config surface offers, in table order.
pub fn api_rows() -> impl Iterator<Item = &'static ParamRow> {
    PARAMS.iter().filter(|r| r.api)
}

/// The rows whose value the device keeps (RAM, saved by WRITE_FLASH).
pub fn settings() -> impl Iterator<Item = &'static ParamRow> {
    PARAMS.iter().filter(|r| r.is_setting())
}

/// The rows an INFO block's fields show.
pub fn fields_of(block: InfoBlock) -> impl Iterator<Item = (&'static ParamRow, Field)> {
    PARAMS
        .iter()
        .filter_map(move |r| r.read_back.filter(|f| f.block == block).map(|f| (r, f)))
}

#[cfg(test)]
pub(crate) mod tests;
