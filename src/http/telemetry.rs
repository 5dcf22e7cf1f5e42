//! Snapshot → physical-unit views shared by the device, bus and control
//! areas. Raw values stay beside the physical ones where users need them.

use std::time::Instant;

use serde::Serialize;
use utoipa::ToSchema;

use crate::bus::firmware::{DeviceFirmware, FirmwareSource};
use crate::bus::handle::DeviceState;
use crate::bus::Setpoint;
use crate::hands::Calibration;
use crate::protocol::params::Revision;
use crate::protocol::status::{active_fault, fault_history, fault_name, fsm_name, fsm_name_in};
use crate::protocol::units::{self, FirmwareVersion};
use crate::protocol::CtrlMode;
use crate::protocol::{Info01, Info02};

pub(crate) use crate::control::device::{
    firmware_of, measured_angle_raw, revision_of, ASSUMED_FIRMWARE,
};

/// A fault code decoded to names.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct FaultView {
    /// err_code as sent.
    #[schema(example = 0)]
    pub code: u8,
    /// Name of the active fault (low nibble), `none` when healthy.
    #[schema(example = "none")]
    pub active: &'static str,
    /// Name of the latched fault history (high nibble, rev 2.0.8 firmware).
    #[schema(example = "none")]
    pub history: &'static str,
}

impl FaultView {
    pub(crate) fn new(code: u8) -> Self {
        Self {
            code,
            active: fault_name(active_fault(code)),
            history: fault_name(fault_history(code)),
        }
    }
}

/// INFO_01 decoded: state and health.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct StatusView {
    /// The fsm code as sent (raw; `state` names it).
    #[schema(example = 7)]
    pub state_code: u8,
    /// `ready`, `align`, `run`, `fault`, ...
    #[schema(example = "run")]
    pub state: &'static str,
    pub fault: FaultView,
    #[schema(example = 128)]
    pub soft_ver: u8,
    #[schema(example = "1.2.8")]
    pub firmware: String,
    #[schema(example = 31.0)]
    pub temp_c: f64,
    #[schema(example = 45.5)]
    pub angle_deg: f64,
    #[schema(example = 12.1)]
    pub vbus_v: f64,
    /// The 8 data bytes as received, hex.
    #[schema(example = "07 00 80 51 C0 16 0D 06")]
    pub raw: String,
    /// Milliseconds since this block was received.
    #[schema(example = 120.5)]
    pub age_ms: f64,
}

/// INFO_02 decoded: fast telemetry.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct MotionView {
    #[schema(example = 45.5)]
    pub angle_deg: f64,
    /// Output-shaft speed, °/s.
    #[schema(example = 21.1)]
    pub speed_dps: f64,
    /// Rotor speed before the 568.81:1 gearbox (raw-side; `speed_dps` is the output's).
    #[schema(example = 2000.0)]
    pub rotor_speed_rpm: f64,
    #[schema(example = 0.01)]
    pub d_current_a: f64,
    #[schema(example = 0.25)]
    pub q_current_a: f64,
    #[schema(example = "00 00 B6 02 E6 07 C0 16")]
    pub raw: String,
    #[schema(example = 8.2)]
    pub age_ms: f64,
}

/// A target in physical units (the joint's calibrated frame) with its raw
/// wire values (the device's).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct TargetView {
    #[schema(example = 45.0)]
    pub position_deg: f64,
    /// Output-shaft °/s: the speed limit in position mode, the speed in speed mode.
    #[schema(example = 30.0)]
    pub speed_dps: f64,
    #[schema(example = 5760)]
    pub pos_ref_raw: i16,
    #[schema(example = 1966)]
    pub spd_ref_raw: i16,
}

impl TargetView {
    /// `mode`: in speed mode the speed is signed (and turns with a flip);
    /// in position mode it is a limit, never negative.
    pub(crate) fn new(
        sp: Setpoint,
        fw: FirmwareVersion,
        cal: &Calibration,
        mode: Option<CtrlMode>,
    ) -> Self {
        let dps = round3(units::speed_dps(sp.spd_ref, fw));
        Self {
            position_deg: cal.to_joint(units::angle_deg(sp.pos_ref)),
            speed_dps: if mode == Some(CtrlMode::Speed) {
                cal.sign() * dps
            } else {
                dps
            },
            pos_ref_raw: sp.pos_ref,
            spd_ref_raw: sp.spd_ref,
        }
    }
}

/// A reset (power cut, reboot) the daemon detected.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct ResetView {
    /// What showed it: `announcement` (its unsolicited power-up INFO_01)
    /// or `state_dropped` (ready again while the daemon believed it enabled).
    #[schema(example = "state_dropped")]
    pub seen: &'static str,
    /// State before (`unknown` if never read) and in the reply that showed it.
    #[schema(example = "run")]
    pub state_before: &'static str,
    #[schema(example = "ready")]
    pub state: &'static str,
    /// Milliseconds since it was detected.
    #[schema(example = 5230.0)]
    pub age_ms: f64,
}

pub(crate) fn reset_view(dev: &DeviceState, now: Instant) -> Option<ResetView> {
    dev.last_reset.map(|r| ResetView {
        seen: r.seen.name(),
        state_before: r.fsm_before.map_or("unknown", fsm_name),
        state: fsm_name(r.fsm),
        age_ms: age_ms(r.at, now),
    })
}

/// Why the joint is disabled, if the daemon knows: `reset`, `fault`,
/// `estop`, `request`, `on_start`, `shutdown`.
pub(crate) fn disabled_reason(dev: &DeviceState) -> Option<&'static str> {
    dev.disabled_reason.map(|r| r.name())
}

pub(crate) use crate::protocol::frame_json::hex;

/// Thousandths are below anything the wire resolves; more digits are noise.
pub(crate) fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn age_ms(at: Instant, now: Instant) -> f64 {
    now.saturating_duration_since(at).as_secs_f64() * 1000.0
}

/// The protocol revision a device speaks, and how the daemon knows.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct RevisionView {
    /// `2.0.1` or `2.0.8`: what the config surface offers and how state codes read.
    #[schema(example = "2.0.8")]
    pub revision: &'static str,
    /// `config` (the bus's `firmware` setting) or `detected` (the device
    /// answered an INFO_07 read: 2.0.8; or stayed silent to it: 2.0.1).
    #[schema(value_type = String, example = "detected")]
    pub source: FirmwareSource,
    /// INFO_07's 8 data bytes, hex: the serial number (rev 2.0.8; the
    /// layout is unpublished, so the bytes are given as they came).
    #[schema(example = "39 30 00 00 00 00 00 00")]
    pub serial_number: Option<String>,
}

impl RevisionView {
    pub(crate) fn new(f: &DeviceFirmware) -> Self {
        Self {
            revision: f.revision.as_str(),
            source: f.source,
            serial_number: f.serial.as_ref().map(|s| hex(s)),
        }
    }
}

/// INFO_01 in the joint's calibrated frame (`cal`).
pub(crate) fn status_view(
    info: &Info01,
    revision: Option<Revision>,
    cal: &Calibration,
    at: Instant,
    now: Instant,
) -> StatusView {
    StatusView {
        state_code: info.fsm,
        state: fsm_name_in(info.fsm, revision),
        fault: FaultView::new(info.err_code),
        soft_ver: info.soft_ver,
        firmware: info.firmware().dotted(),
        temp_c: info.temp_c(),
        angle_deg: cal.to_joint(info.angle_deg()),
        vbus_v: info.vbus_v(),
        raw: hex(&info.to_bytes()),
        age_ms: age_ms(at, now),
    }
}

/// INFO_02 in the joint's calibrated frame (`cal`): a flip turns the
/// angle, the speeds and the torque-making (q) current around.
pub(crate) fn motion_view(
    info: &Info02,
    fw: FirmwareVersion,
    cal: &Calibration,
    at: Instant,
    now: Instant,
) -> MotionView {
    let rpm = cal.sign() * info.speed_rpm(fw);
    MotionView {
        angle_deg: cal.to_joint(info.angle_deg()),
        speed_dps: round3(units::output_deg_per_s(rpm)),
        rotor_speed_rpm: rpm,
        d_current_a: units::current_a(info.d_cur),
        q_current_a: cal.sign() * units::current_a(info.q_cur),
        raw: hex(&info.to_bytes()),
        age_ms: age_ms(at, now),
    }
}
