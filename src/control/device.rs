//! What a device's published state says, for the control core and every
//! front-end: its firmware's speed base and revision, whether it drives its
//! motor, where it is and where it was last sent.

use crate::bus::handle::DeviceState;
use crate::protocol::params::Revision;
use crate::protocol::status::fsm;
use crate::protocol::units::FirmwareVersion;
use crate::protocol::Info01;

/// The speed base to assume before a device has reported its firmware: the
/// newer 50000 rpm base, so an rpm request maps to at most the asked speed
/// on older firmware (40000 rpm base), never more.
pub const ASSUMED_FIRMWARE: FirmwareVersion = FirmwareVersion::SPEED_BASE_50K;

/// The firmware a device reported in INFO_01, or [`ASSUMED_FIRMWARE`].
pub fn firmware_of(dev: &DeviceState) -> FirmwareVersion {
    dev.firmware_version()
}

/// Whether the device runs (or is aligning towards running): the states in
/// which targets and jogs act.
pub fn is_enabled(info: &Info01) -> bool {
    info.fsm == fsm::RUN || info.fsm == fsm::ALIGN
}

/// The revision a device is known to run, if known.
pub fn revision_of(dev: &DeviceState) -> Option<Revision> {
    dev.firmware.map(|f| f.revision)
}

/// Where a joint is headed: the last target sent, else where it was
/// measured (what a pose saved from a hand records; paths start from the
/// measured angle instead, [`measured_angle_raw`]).
pub fn commanded_or_measured_raw(dev: &DeviceState) -> Option<i16> {
    dev.target_sent
        .map(|t| t.pos_ref)
        .or_else(|| measured_angle_raw(dev))
}

/// Latest angle the daemon knows: INFO_02 if fresher than INFO_01.
pub fn measured_angle_raw(dev: &DeviceState) -> Option<i16> {
    match (&dev.info01, &dev.info02) {
        (Some((a, ta)), Some((b, tb))) => Some(if tb >= ta { b.angle } else { a.angle }),
        (Some((a, _)), None) => Some(a.angle),
        (None, Some((b, _))) => Some(b.angle),
        (None, None) => None,
    }
}
