//! The writable parameters of SPEC §4.3 by their API names: physical ↔ raw
//! conversion, the index each is written at, and where its value sits in the
//! INFO_03..06 blocks.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::{ApiError, ApiResult};
use crate::protocol::command::index;
use crate::protocol::params;
use crate::protocol::units;
use crate::protocol::{ConfigParam, Gains, Info04, Info05, Info06};

/// One writable parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Param {
    PosKp,
    PosKd,
    SpdKp,
    SpdKi,
    LpfLevel,
    MaxCurrent,
    ProtectCurrentLimit,
    ProtectCurrentLv1,
    ProtectDelay,
    RecoverCurrent,
    RecoverWindow,
    BurstCold,
    BurstPlus,
}

/// The INFO blocks that hold every parameter.
#[derive(Debug, Clone, Copy)]
pub struct Blocks {
    pub gains: Gains,
    pub info04: Info04,
    pub info05: Info05,
    pub info06: Info06,
}

impl Param {
    pub fn name(self) -> &'static str {
        match self {
            Self::PosKp => "pos_kp",
            Self::PosKd => "pos_kd",
            Self::SpdKp => "spd_kp",
            Self::SpdKi => "spd_ki",
            Self::LpfLevel => "lpf_level",
            Self::MaxCurrent => "max_current_a",
            Self::ProtectCurrentLimit => "protect_current_limit_a",
            Self::ProtectCurrentLv1 => "protect_current_lv1_a",
            Self::ProtectDelay => "protect_delay_ms",
            Self::RecoverCurrent => "recover_current_a",
            Self::RecoverWindow => "recover_window_ms",
            Self::BurstCold => "burst_cold_ms",
            Self::BurstPlus => "burst_plus_ms",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Self::PosKp | Self::PosKd | Self::SpdKp | Self::SpdKi | Self::LpfLevel => "",
            Self::MaxCurrent
            | Self::ProtectCurrentLimit
            | Self::ProtectCurrentLv1
            | Self::RecoverCurrent => "A",
            Self::ProtectDelay | Self::RecoverWindow | Self::BurstCold | Self::BurstPlus => "ms",
        }
    }

    /// The config index a write of this parameter uses.
    pub fn index(self) -> u8 {
        match self {
            Self::PosKp => index::SET_POS_KP,
            Self::PosKd => index::SET_POS_KD,
            Self::SpdKp => index::SET_SPD_KP,
            Self::SpdKi => index::SET_SPD_KI,
            Self::LpfLevel => index::POS_LPF_LV,
            Self::MaxCurrent => index::MAX_CUR,
            Self::ProtectCurrentLimit => index::PROTECT_CUR_LIMIT,
            Self::ProtectCurrentLv1 => index::PROTECT_CUR_LV1,
            Self::ProtectDelay => index::CUR_LV1_DELAY,
            Self::RecoverCurrent => index::RECV_CUR,
            Self::RecoverWindow => index::CUR_RECV_WIN,
            Self::BurstCold => index::COLD_TIME,
            Self::BurstPlus => index::PLUS_TIME,
        }
    }

    /// The raw value of this parameter in the INFO blocks.
    pub fn raw_in(self, b: &Blocks) -> u16 {
        match self {
            Self::PosKp => b.gains.pos_kp,
            Self::PosKd => b.gains.pos_kd,
            Self::SpdKp => b.gains.spd_kp,
            Self::SpdKi => b.gains.spd_ki,
            Self::LpfLevel => u16::from(b.info04.lpf_level),
            Self::MaxCurrent => b.info04.max_current,
            Self::ProtectCurrentLimit => b.info04.protect_limit,
            Self::ProtectCurrentLv1 => b.info05.protect_cur_lv1,
            Self::ProtectDelay => b.info05.protect_delay_lv1_ms,
            Self::RecoverCurrent => b.info05.recv_cur,
            Self::RecoverWindow => b.info05.recover_delay_ms,
            Self::BurstCold => u16::from(b.info06.cold_dt),
            Self::BurstPlus => u16::from(b.info06.plus_t),
        }
    }

    /// Raw → physical.
    pub fn physical(self, raw: u16) -> f64 {
        match self {
            Self::PosKp | Self::PosKd | Self::SpdKp => units::gain_q12(raw),
            Self::SpdKi => units::gain_ki(raw),
            Self::LpfLevel | Self::ProtectDelay | Self::RecoverWindow => f64::from(raw),
            Self::MaxCurrent
            | Self::ProtectCurrentLimit
            | Self::ProtectCurrentLv1
            | Self::RecoverCurrent => units::current_limit_a(raw),
            Self::BurstCold | Self::BurstPlus => {
                f64::from(units::burst_ms(u8::try_from(raw).unwrap_or(u8::MAX)))
            }
        }
    }

    /// Physical → the typed write, range-checked (422 naming field and range).
    pub fn to_config(self, value: f64) -> ApiResult<ConfigParam> {
        let field = self.name();
        Ok(match self {
            Self::PosKp => ConfigParam::PosKp(checked(field, units::gain_q12_to_raw(value))?),
            Self::PosKd => ConfigParam::PosKd(checked(field, units::gain_q12_to_raw(value))?),
            Self::SpdKp => ConfigParam::SpdKp(checked(field, units::gain_q12_to_raw(value))?),
            Self::SpdKi => ConfigParam::SpdKi(checked(field, units::gain_ki_to_raw(value))?),
            Self::LpfLevel => ConfigParam::PosLpf(lpf_level(value)?),
            Self::MaxCurrent => {
                ConfigParam::MaxCur(checked(field, units::current_limit_to_raw(value))?)
            }
            Self::ProtectCurrentLimit => {
                ConfigParam::ProtectCurLimit(checked(field, units::current_limit_to_raw(value))?)
            }
            Self::ProtectCurrentLv1 => {
                ConfigParam::ProtectCurLv1(checked(field, units::current_limit_to_raw(value))?)
            }
            Self::ProtectDelay => {
                ConfigParam::CurLv1DelayMs(checked(field, units::duration_ms_to_raw(value))?)
            }
            Self::RecoverCurrent => {
                ConfigParam::RecvCur(checked(field, units::current_limit_to_raw(value))?)
            }
            Self::RecoverWindow => {
                ConfigParam::CurRecvWinMs(checked(field, units::duration_ms_to_raw(value))?)
            }
            Self::BurstCold => {
                ConfigParam::ColdTime(checked(field, units::burst_ms_to_raw(value))?)
            }
            Self::BurstPlus => {
                ConfigParam::PlusTime(checked(field, units::burst_ms_to_raw(value))?)
            }
        })
    }
}

fn checked<T>(field: &str, r: Result<T, units::UnitError>) -> ApiResult<T> {
    r.map_err(|e| ApiError::from_unit(field, e))
}

/// Smoothing levels are whole numbers 0..=5.
fn lpf_level(value: f64) -> ApiResult<u8> {
    let max = params::by_index(index::POS_LPF_LV).map_or(0.0, |r| f64::from(r.range.1));
    if !(0.0..=max).contains(&value) {
        return Err(ApiError::out_of_range("lpf_level", value, (0.0, max), ""));
    }
    if value.fract() != 0.0 {
        return Err(ApiError::invalid(
            "lpf_level",
            format!("lpf_level = {value} must be a whole number 0..=5"),
        ));
    }
    Ok(value as u8)
}

/// A parameter's value in physical units with the raw value beside it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ParamValue {
    #[schema(example = 0.5)]
    pub value: f64,
    #[schema(example = 2913)]
    pub raw: u16,
    /// `A`, `ms`, or empty for gains and levels.
    #[schema(example = "A")]
    pub unit: &'static str,
    /// The config index a write uses.
    #[schema(example = 18)]
    pub index: u8,
}

impl ParamValue {
    pub fn new(p: Param, raw: u16) -> Self {
        Self {
            value: p.physical(raw),
            raw,
            unit: p.unit(),
            index: p.index(),
        }
    }
}

/// Any subset of the writable parameters, in physical units. Written to RAM
/// and verified by read-back; `POST .../config/persist` keeps them over a power cycle.
#[derive(Debug, Default, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"pos_kp": 1.25, "max_current_a": 2.0, "burst_plus_ms": 100.0}))]
pub struct ConfigPatch {
    /// Position loop KP, 0..<8.0 (Q12).
    #[schema(example = 1.25, minimum = 0.0, maximum = 7.999755859375)]
    pub pos_kp: Option<f64>,
    /// Position loop KD, 0..<8.0 (Q12).
    #[schema(minimum = 0.0, maximum = 7.999755859375)]
    pub pos_kd: Option<f64>,
    /// Speed loop KP, 0..<8.0 (Q12).
    #[schema(minimum = 0.0, maximum = 7.999755859375)]
    pub spd_kp: Option<f64>,
    /// Speed loop KI, 0..<1.0 (Q15).
    #[schema(minimum = 0.0, maximum = 0.999969482421875)]
    pub spd_ki: Option<f64>,
    /// Position smoothing level, 0..=5 (higher = smoother).
    #[schema(example = 2, minimum = 0, maximum = 5, multiple_of = 1)]
    pub lpf_level: Option<f64>,
    /// Maximum output current, 0..=5.625 A.
    #[schema(example = 2.0, minimum = 0.0, maximum = 5.625)]
    pub max_current_a: Option<f64>,
    /// Current cap while protection is active, 0..=5.625 A.
    #[schema(minimum = 0.0, maximum = 5.625)]
    pub protect_current_limit_a: Option<f64>,
    /// Protection level-1 threshold, 0..=5.625 A.
    #[schema(minimum = 0.0, maximum = 5.625)]
    pub protect_current_lv1_a: Option<f64>,
    /// Time above the threshold before protection engages, 0..=65000 ms.
    #[schema(minimum = 0.0, maximum = 65000.0)]
    pub protect_delay_ms: Option<f64>,
    /// Recovery threshold, 0..=5.625 A.
    #[schema(minimum = 0.0, maximum = 5.625)]
    pub recover_current_a: Option<f64>,
    /// Time below recovery threshold before protection releases, 0..=65000 ms.
    #[schema(minimum = 0.0, maximum = 65000.0)]
    pub recover_window_ms: Option<f64>,
    /// Burst cool-down, multiples of 25 ms, 0..=6375 ms.
    #[schema(minimum = 0.0, maximum = 6375.0, multiple_of = 25.0)]
    pub burst_cold_ms: Option<f64>,
    /// Burst duration, multiples of 25 ms, 0..=6375 ms.
    #[schema(example = 100.0, minimum = 0.0, maximum = 6375.0, multiple_of = 25.0)]
    pub burst_plus_ms: Option<f64>,
}

impl ConfigPatch {
    /// The parameters given, in a fixed order (gains, smoothing, currents, protection, burst).
    pub fn entries(&self) -> Vec<(Param, f64)> {
        let all = [
            (Param::PosKp, self.pos_kp),
            (Param::PosKd, self.pos_kd),
            (Param::SpdKp, self.spd_kp),
            (Param::SpdKi, self.spd_ki),
            (Param::LpfLevel, self.lpf_level),
            (Param::MaxCurrent, self.max_current_a),
            (Param::ProtectCurrentLimit, self.protect_current_limit_a),
            (Param::ProtectCurrentLv1, self.protect_current_lv1_a),
            (Param::ProtectDelay, self.protect_delay_ms),
            (Param::RecoverCurrent, self.recover_current_a),
            (Param::RecoverWindow, self.recover_window_ms),
            (Param::BurstCold, self.burst_cold_ms),
            (Param::BurstPlus, self.burst_plus_ms),
        ];
        all.into_iter()
            .filter_map(|(p, v)| v.map(|v| (p, v)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physical_values_round_trip_through_raw() {
        let cases = [
            (Param::PosKp, 1.25),
            (Param::SpdKi, 0.5),
            (Param::LpfLevel, 3.0),
            (Param::MaxCurrent, 2.0),
            (Param::ProtectDelay, 600.0),
            (Param::BurstPlus, 100.0),
        ];
        for (p, v) in cases {
            let (idx, raw) = p.to_config(v).unwrap().index_value();
            assert_eq!(idx, p.index(), "{}", p.name());
            assert!(
                (p.physical(raw) - v).abs() < 1e-3,
                "{}: {v} -> {raw}",
                p.name()
            );
        }
    }

    #[test]
    fn out_of_range_and_fractional_values_are_422() {
        for (p, v) in [
            (Param::LpfLevel, 6.0),
            (Param::LpfLevel, 1.5),
            (Param::MaxCurrent, 6.0),
            (Param::BurstCold, 30.0),
            (Param::PosKd, -0.1),
            (Param::SpdKi, f64::INFINITY),
        ] {
            let err = p.to_config(v).unwrap_err();
            assert_eq!(err.problem.status, 422);
            assert_eq!(err.problem.field.as_deref(), Some(p.name()));
        }
    }
}
