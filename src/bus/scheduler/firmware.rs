//! Which device is asked its firmware revision next, and when silence is
//! the answer (V2.0.1 does not know index 32).

use super::Scheduler;
use crate::bus::firmware::{DeviceFirmware, FirmwareSetting, FirmwareSource};
use crate::protocol::params::Revision;

impl Scheduler {
    /// True when an online device's revision is still to be asked.
    pub(super) fn probe_wanted(&self) -> bool {
        self.reg
            .firmware_unknown()
            .into_iter()
            .any(|id| self.firmware.for_id(id) == FirmwareSetting::Auto)
    }

    /// Records the configured revision of devices the config names, and
    /// returns the first online device whose revision must be asked.
    pub(super) fn firmware_to_ask(&mut self) -> Option<u8> {
        for id in self.reg.firmware_unknown() {
            match self.firmware.for_id(id) {
                FirmwareSetting::Auto => return Some(id),
                FirmwareSetting::Fixed(revision) => self.reg.set_firmware(
                    id,
                    DeviceFirmware {
                        revision,
                        source: FirmwareSource::Config,
                        serial: None,
                    },
                ),
            }
        }
        None
    }

    /// The revision `id` told (it answered a probe).
    pub(crate) fn firmware_known(&mut self, id: u8, firmware: DeviceFirmware) {
        self.reg.set_firmware(id, firmware);
    }

    /// A probe of `id` went unanswered. After `probe_attempts` in a row (and
    /// no missed poll meanwhile, which resets the count) the silence is the
    /// answer: V2.0.1 does not know index 32. Returns the revision then.
    pub(crate) fn probe_unanswered(&mut self, id: u8) -> Option<Revision> {
        if self.reg.probe_silence(id) < self.probe_attempts {
            return None;
        }
        self.reg.set_firmware(
            id,
            DeviceFirmware {
                revision: Revision::V2_0_1,
                source: FirmwareSource::Detected,
                serial: None,
            },
        );
        Some(Revision::V2_0_1)
    }
}
