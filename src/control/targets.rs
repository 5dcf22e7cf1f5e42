//! Targets in physical units → raw setpoints: soft limits first, then the
//! wire range via [`crate::protocol::units`], with the speed base of the
//! device's own firmware; a joint still aligning takes no target. Also the
//! "is it enabled?" check that jogs and targets need.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::device::{firmware_of, measured_angle_raw, revision_of};
use super::error::{ControlError, ControlResult};
use super::limits::JointLimits;
use crate::bus::authority::Epoch;
use crate::bus::handle::DeviceState;
use crate::bus::{BusHandle, Setpoint};
use crate::hands::Calibration;
use crate::protocol::status::{fsm, fsm_name_in};
use crate::protocol::units;
use crate::protocol::CtrlMode;

/// Speed limit of a position target that names none, output °/s (about
/// 2840 rotor rpm): slow enough to be safe, fast enough to see.
pub(crate) const DEFAULT_SPEED_LIMIT_DPS: f64 = 30.0;
/// How long a target request waits to see its frame written before
/// answering 202 instead of 200.
pub(crate) const WIRE_ACK_WAIT: Duration = Duration::from_millis(250);

/// A target for one joint. Position mode: `position_deg` (required) and
/// `speed_dps` as the speed limit (default 30 °/s, capped by the soft
/// limit). Speed mode: `speed_dps` (signed, required) only.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"position_deg": 45.0, "speed_dps": 30.0}))]
pub(crate) struct TargetRequest {
    /// Output angle, degrees (−255..=255, narrowed by soft limits).
    #[schema(example = 45.0, minimum = -255.0, maximum = 255.0)]
    pub position_deg: Option<f64>,
    /// Output-shaft °/s: the speed limit in position mode (≥ 0), the speed
    /// in speed mode (signed); within the firmware's base speed (50000 rotor
    /// rpm, 527 °/s, from 1.2.4; else 40000 rpm, 422 °/s).
    #[schema(example = 30.0, minimum = -527.0, maximum = 527.0)]
    pub speed_dps: Option<f64>,
}

/// Converts one joint's target, given in its calibrated frame (`cal`);
/// `field` prefixes error field names (`targets[2].` in a group request).
/// A valid target for a joint that aligns is refused (409 `not-aligned`).
pub(crate) fn setpoint(
    dev: &DeviceState,
    limits: &JointLimits,
    cal: &Calibration,
    req: &TargetRequest,
    field: &str,
) -> ControlResult<Setpoint> {
    let sp = checked_setpoint(dev, limits, cal, req, field)?;
    not_aligning(dev, field)?;
    Ok(sp)
}

/// [`setpoint`]'s value checks and conversion, whatever the joint's state.
fn checked_setpoint(
    dev: &DeviceState,
    limits: &JointLimits,
    cal: &Calibration,
    req: &TargetRequest,
    field: &str,
) -> ControlResult<Setpoint> {
    if dev.mode == Some(CtrlMode::Speed) {
        return speed_setpoint(dev, limits, cal, req, field);
    }
    if dev.mode == Some(CtrlMode::Current) {
        // Its reference is a current, which jointd does not stream (yet):
        // a position or speed sent now would be taken as something else.
        return Err(ControlError::conflict(
            "wrong-mode",
            "Joint in current mode",
            format!(
                "joint {} is in current mode: position and speed targets do not apply \
                 (set its mode to position or speed first)",
                dev.dev_id
            ),
        ));
    }
    let names = Names::new(field, dev.dev_id);
    let fw = firmware_of(dev);
    let deg = req.position_deg.ok_or_else(|| {
        ControlError::invalid(
            &names.position().to_string(),
            format!(
                "{} is in position mode: position_deg is required",
                names.who()
            ),
        )
    })?;
    let device_deg = limits.check_joint_position(cal, &names.position(), deg, &names.who())?;
    let pos_ref = units::angle_to_raw(device_deg)
        .map_err(|e| ControlError::from_unit(&names.position().to_string(), e))?;
    let default_dps = limits
        .max_speed_dps
        .map_or(DEFAULT_SPEED_LIMIT_DPS, |m| m.min(DEFAULT_SPEED_LIMIT_DPS));
    let dps = req.speed_dps.unwrap_or(default_dps);
    limits.check_motion_speed(&names.speed(), dps, fw, &names.who())?;
    let spd_ref = units::speed_limit_dps_to_raw(dps, fw)
        .map_err(|e| ControlError::from_unit(&names.speed().to_string(), e))?;
    Ok(Setpoint { pos_ref, spd_ref })
}

/// 409 while the joint aligns its encoder after its first enable (fsm
/// `align`, about a second): it stands still until it runs, and a target
/// accepted now would read as taken while nothing moves. Every front-end's
/// targets come through [`setpoint`], so each refuses it alike. The enable
/// confirms the state it reached, so the snapshot says `align` right after.
fn not_aligning(dev: &DeviceState, field: &str) -> ControlResult<()> {
    if !dev
        .info01
        .as_ref()
        .is_some_and(|(i, _)| i.fsm == fsm::ALIGN)
    {
        return Ok(());
    }
    let err = ControlError::conflict(
        "not-aligned",
        "Joint still aligning",
        format!(
            "joint {} is aligning its encoder after its enable and stands still until it \
             runs: send the target once its state is `run`",
            dev.dev_id
        ),
    );
    let field = field.trim_end_matches('.');
    Err(if field.is_empty() {
        err
    } else {
        err.with_field(field)
    })
}

/// The names a target's errors give, written out only when one is raised
/// (a teleop stream converts thousands of targets a second).
struct Names<'a> {
    field: &'a str,
    id: u8,
}

impl<'a> Names<'a> {
    fn new(field: &'a str, id: u8) -> Self {
        Self { field, id }
    }

    fn who(&self) -> JointWho {
        JointWho(self.id)
    }

    fn position(&self) -> FieldName<'a> {
        FieldName(self.field, "position_deg")
    }

    fn speed(&self) -> FieldName<'a> {
        FieldName(self.field, "speed_dps")
    }
}

/// "joint 3".
struct JointWho(u8);

impl std::fmt::Display for JointWho {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "joint {}", self.0)
    }
}

/// A field after its prefix: "targets[2]." and "position_deg".
struct FieldName<'a>(&'a str, &'static str);

impl std::fmt::Display for FieldName<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}", self.0, self.1)
    }
}

/// Speed mode: a signed speed only; the position slot keeps the last target
/// (or the measured angle), since a broadcast carries both.
fn speed_setpoint(
    dev: &DeviceState,
    limits: &JointLimits,
    cal: &Calibration,
    req: &TargetRequest,
    field: &str,
) -> ControlResult<Setpoint> {
    let names = Names::new(field, dev.dev_id);
    if req.position_deg.is_some() {
        return Err(ControlError::invalid(
            &names.position().to_string(),
            format!(
                "{} is in speed mode: a position has no effect (set mode to position)",
                names.who()
            ),
        ));
    }
    let dps = req.speed_dps.ok_or_else(|| {
        ControlError::invalid(
            &names.speed().to_string(),
            format!("{} is in speed mode: speed_dps is required", names.who()),
        )
    })?;
    limits.check_speed(&names.speed(), dps, &names.who())?;
    // A flipped joint turns the device the other way.
    let spd_ref = units::speed_dps_to_raw(cal.sign() * dps, firmware_of(dev))
        .map_err(|e| ControlError::from_unit(&names.speed().to_string(), e))?;
    // Not 0 when unknown: a device that reset unseen runs position mode,
    // and takes this slot as its target: where it stands holds it there.
    let pos_ref = measured_angle_raw(dev).ok_or_else(|| {
        ControlError::conflict(
            "no-position",
            "Position unknown",
            format!("{} has not reported its angle yet", names.who()),
        )
    })?;
    Ok(Setpoint { pos_ref, spd_ref })
}

/// 409 unless the daemon enabled the joint and nothing revoked that since
/// (the bus's motion authority, not a telemetry snapshot that may lag an
/// e-stop), and no current limit is owed to it; the joint's motion epoch,
/// under which what follows is admitted.
pub(crate) fn admit(bus: &BusHandle, dev: &DeviceState, what: &str) -> ControlResult<Epoch> {
    let id = dev.dev_id;
    if let Some(owed) = bus.owed_limits().get(id) {
        return Err(ControlError::conflict(
            "current-limit-owed",
            "Current limit not restored yet",
            format!(
                "{what} waits until device {id} has its current limit back ({:.3} A): a grasp or \
                 homing lowered it and could not write it back; jointd writes it and reads it \
                 back as soon as the joint answers again",
                units::current_limit_a(owed)
            ),
        ));
    }
    let grant = bus.grant(id);
    if !grant.mode_settled() {
        return Err(ControlError::conflict(
            "not-enabled",
            "Mode change in progress",
            format!("{what} waits for the mode change of device {id} to finish; try again"),
        ));
    }
    if grant.enabled {
        return Ok(grant.epoch);
    }
    let since = bus
        .authority()
        .last_revoked(id)
        .map_or(String::new(), |r| format!(" (last: {})", r.name()));
    let state = dev
        .info01
        .as_ref()
        .map_or("unknown", |(i, _)| fsm_name_in(i.fsm, revision_of(dev)));
    Err(ControlError::conflict(
        "not-enabled",
        "Device not enabled",
        format!(
            "{what} needs device {id} enabled by jointd since its last e-stop, disable, \
             reset or fault{since}; its state is `{state}` (enable it first)"
        ),
    ))
}

/// [`admit`] for a position target, a move or a pose: the joint must also
/// run position mode.
pub(crate) fn admit_positions(
    bus: &BusHandle,
    dev: &DeviceState,
    what: &str,
) -> ControlResult<Epoch> {
    let epoch = admit(bus, dev, what)?;
    if !bus.grant(dev.dev_id).takes_positions() {
        return Err(ControlError::conflict(
            "wrong-mode",
            "Joint not in position mode",
            format!(
                "{what} needs device {} in position mode (set its mode to position first)",
                dev.dev_id
            ),
        ));
    }
    Ok(epoch)
}

/// 409 unless the joint may take commands ([`admit`]).
pub(crate) async fn ensure_enabled(
    bus: &BusHandle,
    dev: &DeviceState,
    what: &str,
) -> ControlResult<()> {
    admit(bus, dev, what).map(drop)
}

/// Waits (briefly) until the setpoint write `seq` is on the wire.
pub(crate) async fn wait_on_wire(bus: &BusHandle, seq: u64) -> bool {
    let mut acks = bus.wire_acks();
    tokio::time::timeout(WIRE_ACK_WAIT, acks.wait_for(|a| a.seq >= seq))
        .await
        .is_ok_and(|r| r.is_ok())
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;
    use crate::protocol::units::FirmwareVersion;
    use crate::protocol::Info01;

    fn dev(mode: CtrlMode, soft_ver: Option<u8>) -> DeviceState {
        DeviceState {
            dev_id: 4,
            online: true,
            mode: Some(mode),
            info01: soft_ver.map(|v| {
                let info = Info01 {
                    soft_ver: v,
                    angle: 1280,
                    ..Default::default()
                };
                (info, Instant::now())
            }),
            ..Default::default()
        }
    }

    fn req(pos: Option<f64>, spd: Option<f64>) -> TargetRequest {
        TargetRequest {
            position_deg: pos,
            speed_dps: spd,
        }
    }

    #[test]
    fn position_mode_uses_the_firmware_speed_base() {
        let limits = JointLimits::default();
        let new_fw = dev(CtrlMode::Position, Some(128));
        let sp = setpoint(
            &new_fw,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(-10.5), Some(units::output_deg_per_s(20000.0))),
            "",
        )
        .unwrap();
        assert_eq!((sp.pos_ref, sp.spd_ref), (-1344, 13107));
        let old_fw = dev(CtrlMode::Position, Some(117));
        let sp = setpoint(
            &old_fw,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(0.0), Some(units::output_deg_per_s(20000.0))),
            "",
        )
        .unwrap();
        assert_eq!(sp.spd_ref, 16384, "40000 rpm base before firmware 1.2.4");
        let err = setpoint(
            &new_fw,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(0.0), Some(-5.0)),
            "",
        )
        .unwrap_err();
        assert_eq!(err.field(), Some("speed_dps"));
        let err = setpoint(
            &new_fw,
            &limits,
            &Calibration::IDENTITY,
            &req(None, Some(5.0)),
            "t.",
        )
        .unwrap_err();
        assert_eq!(err.field(), Some("t.position_deg"));
    }

    #[test]
    fn a_joint_aligning_takes_no_target_and_a_bad_value_is_said_first() {
        let limits = JointLimits::default();
        let mut aligning = dev(CtrlMode::Position, Some(128));
        if let Some((info, _)) = aligning.info01.as_mut() {
            info.fsm = fsm::ALIGN;
        }
        let err = setpoint(
            &aligning,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(10.0), None),
            "targets[1].",
        )
        .unwrap_err();
        match &err {
            ControlError::Conflict { kind, field, .. } => {
                assert_eq!(kind, "not-aligned");
                assert_eq!(field.as_deref(), Some("targets[1]"));
            }
            other => panic!("{other:?}"),
        }
        assert!(err.to_string().contains("once its state is `run`"), "{err}");
        let err = setpoint(
            &aligning,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(1000.0), None),
            "",
        )
        .unwrap_err();
        assert!(matches!(err, ControlError::Invalid { .. }), "{err:?}");
        let mut running = aligning.clone();
        if let Some((info, _)) = running.info01.as_mut() {
            info.fsm = fsm::RUN;
        }
        assert!(setpoint(
            &running,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(10.0), None),
            ""
        )
        .is_ok());
    }

    #[test]
    fn default_speed_limit_respects_the_soft_limit() {
        let limits = JointLimits {
            max_speed_dps: Some(10.0),
            ..Default::default()
        };
        let sp = setpoint(
            &dev(CtrlMode::Position, None),
            &limits,
            &Calibration::IDENTITY,
            &req(Some(1.0), None),
            "",
        );
        let expected =
            units::speed_limit_dps_to_raw(10.0, FirmwareVersion::SPEED_BASE_50K).unwrap();
        assert_eq!(sp.unwrap().spd_ref, expected);
    }

    #[test]
    fn speed_mode_takes_a_signed_speed_and_holds_the_position_slot() {
        let limits = JointLimits::default();
        let d = dev(CtrlMode::Speed, Some(128));
        let sp = setpoint(
            &d,
            &limits,
            &Calibration::IDENTITY,
            &req(None, Some(units::output_deg_per_s(-1000.0))),
            "",
        )
        .unwrap();
        assert_eq!((sp.pos_ref, sp.spd_ref), (1280, -655));
        assert!(setpoint(
            &d,
            &limits,
            &Calibration::IDENTITY,
            &req(Some(3.0), Some(1.0)),
            ""
        )
        .is_err());
        assert!(setpoint(&d, &limits, &Calibration::IDENTITY, &req(None, None), "").is_err());
    }

    #[test]
    fn a_calibrated_target_is_the_device_angle_and_a_flip_turns_the_speed() {
        let cal = Calibration {
            offset_deg: 20.0,
            flip: true,
            range_deg: Some((-10.0, 60.0)),
            homed_at_ms: None,
        };
        let limits = JointLimits {
            min_deg: -30.0,
            max_deg: 90.0,
            max_speed_dps: None,
        };
        let pos = dev(CtrlMode::Position, Some(128));
        // joint 15 deg = device 20 - 15 = 5 deg.
        let sp = setpoint(&pos, &limits, &cal, &req(Some(15.0), None), "").unwrap();
        assert_eq!(sp.pos_ref, units::angle_to_raw(5.0).unwrap());
        let err = setpoint(&pos, &limits, &cal, &req(Some(61.0), None), "").unwrap_err();
        assert!(
            matches!(
                err,
                ControlError::Invalid {
                    kind: crate::control::error::InvalidKind::CalibratedRange,
                    ..
                }
            ),
            "{err:?}"
        );
        // joint 55 deg = device -35 deg: inside the range, past the soft limit
        // (-30..=90 device = -70..=50 joint), told in joint degrees.
        let err = setpoint(&pos, &limits, &cal, &req(Some(55.0), None), "").unwrap_err();
        assert!(err.to_string().contains("-70..=50"), "{err}");
        let spd = dev(CtrlMode::Speed, Some(128));
        let sp = setpoint(&spd, &limits, &cal, &req(None, Some(-10.0)), "").unwrap();
        assert!(
            sp.spd_ref > 0,
            "a flipped joint turns the device the other way"
        );
    }
}
