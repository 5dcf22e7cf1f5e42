//! What observers (tests, the CLI, the dashboard) can see of a simulated
//! device without going through the wire.

use serde::Serialize;

use crate::protocol::params::Revision;
use crate::protocol::CtrlMode;

use super::params::Params;

/// A snapshot of one device's state, physical units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeviceView {
    /// Position on the bus (stable across id changes).
    pub slot: usize,
    pub id: u8,
    /// The protocol revision its firmware implements (`"2.0.1"`, `"2.0.8"`).
    #[serde(serialize_with = "as_text")]
    pub firmware: Revision,
    /// SPEC §5 fsm (0 ready, 5 align, 7 run, 9 fault; rev 2.0.8 adds 1, 2, 6, 8, 10).
    pub fsm: u8,
    /// As INFO_01 carries it (rev 2.0.8: low nibble active, high nibble history).
    pub err_code: u8,
    #[serde(serialize_with = "as_name")]
    pub mode: CtrlMode,
    /// In align, start or run: the motor is powered.
    pub enabled: bool,
    pub aligned: bool,
    pub angle_deg: f64,
    pub target_deg: f64,
    /// Where the reported zero is, in the joint's physical degrees (moved by
    /// jog and UPDATE_FIN_ZERO).
    pub zero_deg: f64,
    pub velocity_deg_s: f64,
    /// Last speed reference (Q15): the limit in position mode.
    pub spd_ref: i16,
    /// Last current reference (Q15 of 5.625 A): rev 2.0.8 current mode.
    pub cur_ref: i16,
    /// The q current the winding carries (the current loop's output; the
    /// reports add measurement noise to it), A.
    pub q_current_a: f64,
    /// The capped q current reference the current loop follows, A.
    pub q_current_ref_a: f64,
    /// How hard the object (if any) pushes back, as the q current that
    /// balances it (N·m through the model's torque constant), A: the true
    /// force on the object.
    pub object_push_a: f64,
    pub temp_c: f64,
    pub vbus_v: f64,
    /// The baud the device listens at.
    pub baud: u32,
    pub silent: bool,
    pub booting: bool,
    pub jogging: bool,
    pub blocked: bool,
    pub protection_active: bool,
    pub bursting: bool,
    pub under_voltage: bool,
    /// RAM parameters (what INFO_03..06 report).
    pub params: Params,
    pub flash: Params,
}

/// The mode by its one name ([`CtrlMode`]'s `Display`).
fn as_name<S: serde::Serializer>(mode: &CtrlMode, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(mode)
}

/// The revision as SPEC writes it.
fn as_text<S: serde::Serializer>(rev: &Revision, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(rev)
}
