//! Raw ↔ physical conversions of SPEC §6, in one place.
//!
//! Conversions to raw round to the nearest step and refuse values outside the
//! range the field can carry (or the device accepts): they never wrap or clamp.

use thiserror::Error;

/// Q7 fixed point: angles and bus voltage.
pub const Q7: f64 = 128.0;
/// Largest raw Q15 value (`0..32767` = 0..100 %).
pub const Q15_MAX: f64 = 32767.0;
/// Full-scale current of a Q15 current field, amperes.
pub const CURRENT_FULL_SCALE_A: f64 = 5.625;
/// Q12 gains: `raw / 4096`.
pub const Q12: f64 = 4096.0;
/// Speed KI is Q15 with a 32768 divisor (SPEC §6).
pub const KI_SCALE: f64 = 32768.0;
/// Temperatures are sent as `°C + 50`.
pub const TEMP_OFFSET_C: f64 = 50.0;
/// Burst cool-down and duration step.
pub const BURST_STEP_MS: u32 = 25;
/// Rotor turns per output turn (rev 2.0.8).
pub const GEAR_RATIO: f64 = 568.81;
/// Position references the device accepts, degrees (SPEC §4.1).
pub const MAX_ANGLE_DEG: f64 = 255.0;
/// Protection durations (indices 21, 23), milliseconds.
pub const MAX_DURATION_MS: f64 = 65000.0;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum UnitError {
    #[error("{quantity} = {value} {unit} is out of range; allowed {min}..={max} {unit}")]
    OutOfRange {
        quantity: &'static str,
        value: f64,
        min: f64,
        max: f64,
        unit: &'static str,
    },
    #[error("{quantity} is not a finite number")]
    NotFinite { quantity: &'static str },
    #[error("{quantity} = {value} {unit} is not a multiple of {step} {unit}")]
    NotMultiple {
        quantity: &'static str,
        value: f64,
        step: u32,
        unit: &'static str,
    },
    #[error("{quantity} = {value} is not one of {allowed}")]
    NotOneOf {
        quantity: &'static str,
        value: f64,
        allowed: &'static str,
    },
}

/// A firmware version as the device reports it (`soft_ver`, 117 → v1.1.7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct FirmwareVersion(pub u8);

impl FirmwareVersion {
    /// The first firmware whose speed base is 50000 rpm (SPEC errata 5).
    pub const SPEED_BASE_50K: FirmwareVersion = FirmwareVersion(124);

    /// Rotor speed at Q15 full scale.
    pub fn speed_base_rpm(self) -> f64 {
        if self >= Self::SPEED_BASE_50K {
            50000.0
        } else {
            40000.0
        }
    }

    /// Dotted form, `117` → `"1.1.7"`.
    pub fn dotted(self) -> String {
        let v = self.0;
        format!("{}.{}.{}", v / 100, (v / 10) % 10, v % 10)
    }
}

/// Checks finiteness and range, then rounds `value * scale` to the nearest integer.
fn to_raw(
    quantity: &'static str,
    unit: &'static str,
    value: f64,
    (min, max): (f64, f64),
    scale: f64,
) -> Result<i64, UnitError> {
    if !value.is_finite() {
        return Err(UnitError::NotFinite { quantity });
    }
    if value < min || value > max {
        return Err(UnitError::OutOfRange {
            quantity,
            value,
            min,
            max,
            unit,
        });
    }
    Ok((value * scale).round() as i64)
}

// ---- angles (Q7 degrees) ----

pub fn angle_deg(raw: i16) -> f64 {
    f64::from(raw) / Q7
}

/// A position reference: −255°..=+255°.
pub fn angle_to_raw(deg: f64) -> Result<i16, UnitError> {
    let raw = to_raw("angle", "deg", deg, (-MAX_ANGLE_DEG, MAX_ANGLE_DEG), Q7)?;
    Ok(raw as i16)
}

// ---- speed (Q15 of the firmware's base rpm) ----

pub fn speed_rpm(raw: i16, fw: FirmwareVersion) -> f64 {
    f64::from(raw) / Q15_MAX * fw.speed_base_rpm()
}

/// A signed rotor speed, within ± the firmware's base speed.
pub fn speed_to_raw(rpm: f64, fw: FirmwareVersion) -> Result<i16, UnitError> {
    let base = fw.speed_base_rpm();
    let raw = to_raw("speed", "rpm", rpm, (-base, base), Q15_MAX / base)?;
    Ok(raw as i16)
}

/// A position-mode speed limit: 0..=base rpm.
pub fn speed_limit_to_raw(rpm: f64, fw: FirmwareVersion) -> Result<i16, UnitError> {
    let base = fw.speed_base_rpm();
    let raw = to_raw("speed limit", "rpm", rpm, (0.0, base), Q15_MAX / base)?;
    Ok(raw as i16)
}

/// Output-shaft speed for a rotor speed (through the gearbox).
pub fn output_deg_per_s(rotor_rpm: f64) -> f64 {
    rotor_rpm * 6.0 / GEAR_RATIO
}

/// Output-shaft °/s of a speed reference (the user-facing speed).
pub fn speed_dps(raw: i16, fw: FirmwareVersion) -> f64 {
    output_deg_per_s(speed_rpm(raw, fw))
}

/// A signed output speed, °/s, within ± the firmware's base speed at the
/// output (so an error names the range in the unit the user gave).
pub fn speed_dps_to_raw(dps: f64, fw: FirmwareVersion) -> Result<i16, UnitError> {
    let base = output_deg_per_s(fw.speed_base_rpm());
    let raw = to_raw("speed", "°/s", dps, (-base, base), Q15_MAX / base)?;
    Ok(raw as i16)
}

/// A position-mode speed limit at the output: 0..=base, °/s.
pub fn speed_limit_dps_to_raw(dps: f64, fw: FirmwareVersion) -> Result<i16, UnitError> {
    let base = output_deg_per_s(fw.speed_base_rpm());
    let raw = to_raw("speed limit", "°/s", dps, (0.0, base), Q15_MAX / base)?;
    Ok(raw as i16)
}

// ---- current (Q15 of 5.625 A) ----

pub fn current_a(raw: i16) -> f64 {
    f64::from(raw) / Q15_MAX * CURRENT_FULL_SCALE_A
}

/// Current settings (limits, thresholds) are magnitudes: 0..=5.625 A.
pub fn current_limit_a(raw: u16) -> f64 {
    f64::from(raw) / Q15_MAX * CURRENT_FULL_SCALE_A
}

pub fn current_limit_to_raw(amps: f64) -> Result<u16, UnitError> {
    let raw = to_raw(
        "current",
        "A",
        amps,
        (0.0, CURRENT_FULL_SCALE_A),
        Q15_MAX / CURRENT_FULL_SCALE_A,
    )?;
    Ok(raw as u16)
}

// ---- voltage, temperature ----

pub fn volts(raw: u16) -> f64 {
    f64::from(raw) / Q7
}

pub fn volts_to_raw(v: f64) -> Result<u16, UnitError> {
    Ok(to_raw("voltage", "V", v, (0.0, f64::from(u16::MAX) / Q7), Q7)? as u16)
}

pub fn temp_c(raw: u8) -> f64 {
    f64::from(raw) - TEMP_OFFSET_C
}

pub fn temp_to_raw(c: f64) -> Result<u8, UnitError> {
    let raw = to_raw("temperature", "°C", c, (-50.0, 205.0), 1.0)? + TEMP_OFFSET_C as i64;
    Ok(raw as u8)
}

// ---- gains ----

/// POS_KP, POS_KD, SPD_KP: Q12, 0..=8.0 (raw 0..=32767).
pub fn gain_q12(raw: u16) -> f64 {
    f64::from(raw) / Q12
}

pub fn gain_q12_to_raw(gain: f64) -> Result<u16, UnitError> {
    Ok(to_raw("gain", "", gain, (0.0, Q15_MAX / Q12), Q12)? as u16)
}

/// SPD_KI: Q15, 0..<1.0 (raw 0..=32767).
pub fn gain_ki(raw: u16) -> f64 {
    f64::from(raw) / KI_SCALE
}

pub fn gain_ki_to_raw(gain: f64) -> Result<u16, UnitError> {
    Ok(to_raw("speed KI", "", gain, (0.0, Q15_MAX / KI_SCALE), KI_SCALE)? as u16)
}

// ---- durations ----

/// Protection delays (indices 21, 23): 0..=65000 ms.
pub fn duration_ms_to_raw(ms: f64) -> Result<u16, UnitError> {
    Ok(to_raw("duration", "ms", ms, (0.0, MAX_DURATION_MS), 1.0)? as u16)
}

/// Burst cool-down / duration (indices 26, 27): multiples of 25 ms, 0..=6375 ms.
pub fn burst_ms(raw: u8) -> u32 {
    u32::from(raw) * BURST_STEP_MS
}

pub fn burst_ms_to_raw(ms: f64) -> Result<u8, UnitError> {
    let max = f64::from(u8::MAX) * f64::from(BURST_STEP_MS);
    let raw = to_raw(
        "burst time",
        "ms",
        ms,
        (0.0, max),
        1.0 / f64::from(BURST_STEP_MS),
    )?;
    if (raw as f64 * f64::from(BURST_STEP_MS) - ms).abs() > 1e-9 {
        return Err(UnitError::NotMultiple {
            quantity: "burst time",
            value: ms,
            step: BURST_STEP_MS,
            unit: "ms",
        });
    }
    Ok(raw as u8)
}

// ---- whole numbers (levels, modes, ids) ----

/// A whole number within `min..=max` (a smoothing level, a mode, an id).
pub fn whole_to_raw(
    quantity: &'static str,
    unit: &'static str,
    value: f64,
    (min, max): (u16, u16),
) -> Result<u16, UnitError> {
    let raw = to_raw(quantity, unit, value, (f64::from(min), f64::from(max)), 1.0)?;
    if value.fract() != 0.0 {
        return Err(UnitError::NotMultiple {
            quantity,
            value,
            step: 1,
            unit,
        });
    }
    Ok(raw as u16)
}

// ---- saturating encoders: a simulated sensor reports the nearest raw value ----

/// Q7 degrees, clamped to the i16 range.
pub fn angle_raw_saturating(deg: f64) -> i16 {
    saturate_i16(deg * Q7)
}

/// Q15 current, clamped to ±full scale.
pub fn current_raw_saturating(amps: f64) -> i16 {
    saturate_q15(amps / CURRENT_FULL_SCALE_A * Q15_MAX)
}

/// Q15 rotor speed of the firmware's base, clamped to ±full scale.
pub fn speed_raw_saturating(rpm: f64, fw: FirmwareVersion) -> i16 {
    saturate_q15(rpm / fw.speed_base_rpm() * Q15_MAX)
}

/// Q7 volts, clamped to the u16 range.
pub fn volts_raw_saturating(v: f64) -> u16 {
    (v * Q7).round().clamp(0.0, f64::from(u16::MAX)) as u16
}

/// `°C + 50`, clamped to the u8 range.
pub fn temp_raw_saturating(c: f64) -> u8 {
    (c + TEMP_OFFSET_C).round().clamp(0.0, f64::from(u8::MAX)) as u8
}

/// Rotor speed for an output-shaft speed (the inverse of [`output_deg_per_s`]).
pub fn rotor_rpm(output_deg_per_s: f64) -> f64 {
    output_deg_per_s * GEAR_RATIO / 6.0
}

fn saturate_i16(x: f64) -> i16 {
    x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn saturate_q15(x: f64) -> i16 {
    x.round().clamp(-Q15_MAX, Q15_MAX) as i16
}

/// Time one 20-byte frame occupies on the wire: 10 bit times per byte (SPEC §1).
pub fn frame_time_s(baud: u32) -> f64 {
    200.0 / f64::from(baud)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_values_are_refused_not_wrapped() {
        assert!(matches!(
            angle_to_raw(300.0),
            Err(UnitError::OutOfRange { .. })
        ));
        assert!(matches!(
            angle_to_raw(-255.1),
            Err(UnitError::OutOfRange { .. })
        ));
        assert!(matches!(
            current_limit_to_raw(-1.0),
            Err(UnitError::OutOfRange { .. })
        ));
        assert!(matches!(
            current_limit_to_raw(6.0),
            Err(UnitError::OutOfRange { .. })
        ));
        assert!(matches!(
            angle_to_raw(f64::NAN),
            Err(UnitError::NotFinite { .. })
        ));
        assert!(matches!(
            gain_q12_to_raw(8.5),
            Err(UnitError::OutOfRange { .. })
        ));
        assert!(matches!(
            burst_ms_to_raw(30.0),
            Err(UnitError::NotMultiple { .. })
        ));
    }

    #[test]
    fn in_range_values_round_to_the_nearest_step() {
        assert_eq!(angle_to_raw(255.0), Ok(32640));
        assert_eq!(angle_to_raw(-10.1171875), Ok(-1295));
        assert_eq!(current_limit_to_raw(0.5), Ok(2913));
        assert_eq!(gain_q12_to_raw(0.25), Ok(1024));
        assert_eq!(burst_ms_to_raw(75.0), Ok(3));
        assert_eq!(temp_to_raw(29.0), Ok(79));
    }

    #[test]
    fn speed_base_depends_on_firmware() {
        let old = FirmwareVersion(123);
        let new = FirmwareVersion(124);
        assert!((speed_rpm(32767, new) - 50000.0).abs() < 1e-9);
        assert!((speed_rpm(32767, old) - 40000.0).abs() < 1e-9);
        assert_eq!(speed_to_raw(20000.0, new), Ok(13107));
        assert!(speed_to_raw(45000.0, old).is_err());
        assert!(speed_limit_to_raw(-1.0, new).is_err());
        assert_eq!(FirmwareVersion(117).dotted(), "1.1.7");
    }

    #[test]
    fn frame_time_counts_ten_bits_per_byte() {
        assert!((frame_time_s(500_000) - 400e-6).abs() < 1e-12);
    }
}
