//! Features a firmware revision must have: 422 when the device runs an
//! older one (saying which and how the daemon knows), 409 while its
//! revision is not known yet. For current mode, parameters and anything
//! else that exists on rev 2.0.8 only.

use crate::bus::firmware::FirmwareSource;
use crate::bus::handle::DeviceState;
use crate::protocol::params::Revision;

use super::error::{ControlError, ControlResult};

/// Device `id` runs at least `need`; `field` names the request member,
/// `what` the feature asked for.
pub fn require_revision(
    field: &str,
    what: &str,
    need: Revision,
    id: u8,
    dev: &DeviceState,
) -> ControlResult<()> {
    let need_s = need.as_str();
    match dev.firmware {
        Some(f) if f.revision >= need => Ok(()),
        Some(f) => Err(ControlError::invalid(
            field,
            format!(
                "{what} needs rev {need_s} firmware; device {id} runs {} ({})",
                f.revision.as_str(),
                match f.source {
                    FirmwareSource::Config => "set in the config",
                    FirmwareSource::Detected => "detected",
                }
            ),
        )),
        None => Err(ControlError::conflict(
            "firmware-unknown",
            "Firmware revision not known yet",
            format!(
                "{what} needs rev {need_s} firmware and device {id}'s revision is not known yet \
                 (it is asked once the device answers; or set `firmware` in the bus's config)"
            ),
        )
        .with_field(field)),
    }
}
