//! [`Scale`]: which conversion of SPEC §6 a row's raw value takes. The
//! arithmetic is [`crate::protocol::units`]'s; a scale only picks it, names
//! its unit and its physical twin in frame JSON.

use crate::protocol::units::{self, FirmwareVersion, UnitError};
use crate::protocol::values::BaudLevel;

/// How a raw value maps to a physical one (SPEC §6); the arithmetic is
/// [`crate::protocol::units`]'s, this only says which conversion a row uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Scale {
    /// The raw integer is the value (levels, keys, plain numbers).
    Plain,
    /// Q12 gain: `raw / 4096`.
    GainQ12,
    /// Q15 gain (speed KI): `raw / 32768`.
    GainQ15,
    /// Q15 current magnitude: `raw / 32767 × 5.625` A.
    CurrentQ15,
    /// Milliseconds, 1 ms per step.
    Millis,
    /// Burst times: `raw × 25` ms.
    Burst25Ms,
    /// Degrees Celsius, 1 °C per step.
    Celsius,
    /// Q15 rotor speed limit, rpm at the 50000 rpm base (firmware ≥ 1.2.4).
    SpeedQ15,
    /// A device id sent as `new_id << 7`.
    DeviceIdQ7,
    /// A baud level of SPEC §1 (0 = 500000 … 4 = 19200).
    BaudLevel,
    /// A control mode (0 none, 1 speed, 2 position, 3 current).
    CtrlMode,
}

impl Scale {
    /// Unit of the physical value (empty for gains, levels and plain numbers).
    pub fn unit(self) -> &'static str {
        match self {
            Self::CurrentQ15 => "A",
            Self::Millis | Self::Burst25Ms => "ms",
            Self::Celsius => "°C",
            Self::SpeedQ15 => "rpm",
            Self::BaudLevel => "baud",
            _ => "",
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Plain => "plain",
            Self::GainQ12 => "q12",
            Self::GainQ15 => "q15_gain",
            Self::CurrentQ15 => "q15_current",
            Self::Millis => "ms",
            Self::Burst25Ms => "x25ms",
            Self::Celsius => "celsius",
            Self::SpeedQ15 => "q15_speed",
            Self::DeviceIdQ7 => "id_q7",
            Self::BaudLevel => "baud_level",
            Self::CtrlMode => "mode",
        }
    }

    /// The physical twin of `value` in frame JSON (`"amps"` beside the raw value).
    pub fn json_field(self) -> Option<&'static str> {
        match self {
            Self::GainQ12 | Self::GainQ15 => Some("gain"),
            Self::CurrentQ15 => Some("amps"),
            Self::Millis | Self::Burst25Ms => Some("ms"),
            Self::SpeedQ15 => Some("rpm"),
            Self::DeviceIdQ7 => Some("new_id"),
            Self::BaudLevel => Some("baud"),
            Self::CtrlMode => Some("mode"),
            Self::Plain | Self::Celsius => None,
        }
    }

    /// The step a physical value must be a multiple of (values between steps
    /// are refused); `None` when any value is rounded to the nearest step.
    pub fn step(self) -> Option<f64> {
        match self {
            Self::Plain | Self::Celsius | Self::DeviceIdQ7 | Self::CtrlMode => Some(1.0),
            Self::Burst25Ms => Some(f64::from(units::BURST_STEP_MS)),
            _ => None,
        }
    }

    /// True when every physical value is a whole number (printed as an integer).
    pub fn is_whole(self) -> bool {
        !matches!(
            self,
            Self::GainQ12 | Self::GainQ15 | Self::CurrentQ15 | Self::SpeedQ15
        )
    }

    /// Raw → physical. Mode is its number; a baud level its baud (0 if unknown).
    pub fn physical(self, raw: u16) -> f64 {
        match self {
            Self::GainQ12 => units::gain_q12(raw),
            Self::GainQ15 => units::gain_ki(raw),
            Self::CurrentQ15 => units::current_limit_a(raw),
            Self::Burst25Ms => f64::from(units::burst_ms(saturate_u8(raw))),
            Self::SpeedQ15 => units::speed_rpm(
                i16::try_from(raw).unwrap_or(i16::MAX),
                FirmwareVersion::SPEED_BASE_50K,
            ),
            Self::DeviceIdQ7 => f64::from(raw >> 7),
            Self::BaudLevel => {
                BaudLevel::from_raw(saturate_u8(raw)).map_or(0.0, |l| l.baud().into())
            }
            Self::Plain | Self::Millis | Self::Celsius | Self::CtrlMode => f64::from(raw),
        }
    }

    /// Physical → raw, refusing values outside `range` (raw) or between steps.
    pub fn to_raw(
        self,
        quantity: &'static str,
        value: f64,
        range: (u16, u16),
    ) -> Result<u16, UnitError> {
        match self {
            Self::GainQ12 => units::gain_q12_to_raw(value),
            Self::GainQ15 => units::gain_ki_to_raw(value),
            Self::CurrentQ15 => units::current_limit_to_raw(value),
            Self::Millis => units::duration_ms_to_raw(value),
            Self::Burst25Ms => units::burst_ms_to_raw(value).map(u16::from),
            Self::SpeedQ15 => {
                units::speed_limit_to_raw(value, FirmwareVersion::SPEED_BASE_50K).map(|r| r as u16)
            }
            Self::DeviceIdQ7 => {
                let shifted = (range.0 >> 7, range.1 >> 7);
                units::whole_to_raw(quantity, self.unit(), value, shifted).map(|id| id << 7)
            }
            Self::BaudLevel => baud_to_level(quantity, value),
            Self::Plain | Self::Celsius | Self::CtrlMode => {
                units::whole_to_raw(quantity, self.unit(), value, range)
            }
        }
    }
}

fn saturate_u8(raw: u16) -> u8 {
    u8::try_from(raw).unwrap_or(u8::MAX)
}

fn baud_to_level(quantity: &'static str, baud: f64) -> Result<u16, UnitError> {
    let level = BaudLevel::ALL
        .into_iter()
        .find(|l| f64::from(l.baud()) == baud);
    level.map(|l| l as u16).ok_or(UnitError::NotOneOf {
        quantity,
        value: baud,
        allowed: "500000, 230400, 115200, 38400, 19200",
    })
}
