//! Which protocol revision each device speaks, and how the daemon knows.
//!
//! Modules in the field run V2.0.1 or rev 2.0.8 firmware (SPEC: facts marked
//! *(rev 2.0.8)*), and one bus may mix them. A rev 2.0.8 device answers an
//! `INFO_07` read (its serial number); a V2.0.1 device does not know index
//! 32 and stays silent. With `firmware = "auto"` (the default) the owner
//! asks each device once when it is first heard and records the answer;
//! a fixed setting skips the question. The revision decides what the REST
//! config surface offers (indices 28–31, the serial number, current mode)
//! and how state codes are named; jointd's own frames are the same on both
//! (it never sends EN = 0, which the two revisions read differently).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::protocol::ids::parse_id_list;
use crate::protocol::params::Revision;

/// What the config says about one device's firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FirmwareSetting {
    /// Ask the device (an `INFO_07` read when it is first heard).
    #[default]
    Auto,
    /// Take this revision without asking.
    Fixed(Revision),
}

impl FirmwareSetting {
    /// `auto`, `2.0.1` or `2.0.8`.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.trim() {
            "auto" => Ok(Self::Auto),
            t => revision(t).map(Self::Fixed).ok_or_else(|| {
                format!("firmware `{t}` is not one of \"auto\", \"2.0.1\", \"2.0.8\"")
            }),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Fixed(r) => r.as_str(),
        }
    }
}

/// A revision by its dotted name.
pub fn revision(text: &str) -> Option<Revision> {
    [Revision::V2_0_1, Revision::V2_0_8]
        .into_iter()
        .find(|r| r.as_str() == text)
}

impl Serialize for FirmwareSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for FirmwareSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Self::parse(&text).map_err(serde::de::Error::custom)
    }
}

/// The firmware settings of one bus: one for the bus, and per device where
/// a bus mixes revisions (`firmware_by_id = { "9-16" = "2.0.1" }`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FirmwarePolicy {
    pub default: FirmwareSetting,
    pub by_id: BTreeMap<u8, FirmwareSetting>,
}

impl FirmwarePolicy {
    /// The setting that applies to `id`.
    pub fn for_id(&self, id: u8) -> FirmwareSetting {
        self.by_id.get(&id).copied().unwrap_or(self.default)
    }

    /// Builds the per-device part from `"IDS" = "SETTING"` pairs, ids as
    /// `3`, `1-8` or `1,3,5-7`.
    pub fn with_ids<'a>(
        default: FirmwareSetting,
        pairs: impl IntoIterator<Item = (&'a str, FirmwareSetting)>,
    ) -> Result<Self, String> {
        let mut by_id = BTreeMap::new();
        for (ids, setting) in pairs {
            for id in parse_id_list(ids)? {
                if by_id.insert(id, setting).is_some() {
                    return Err(format!("firmware_by_id names device {id} twice"));
                }
            }
        }
        Ok(Self { default, by_id })
    }
}

/// How the daemon came to know a device's revision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FirmwareSource {
    /// The config file says so (`firmware` or `firmware_by_id`).
    Config,
    /// The device answered an `INFO_07` read (2.0.8) or stayed silent to
    /// every attempt while answering its polls (2.0.1).
    Detected,
}

/// A device's revision as the daemon knows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceFirmware {
    pub revision: Revision,
    pub source: FirmwareSource,
    /// INFO_07's data bytes (the serial number; layout unpublished).
    pub serial: Option<[u8; 8]>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_parse_and_name_themselves() {
        for text in ["auto", "2.0.1", "2.0.8"] {
            assert_eq!(FirmwareSetting::parse(text).map(|s| s.name()), Ok(text));
        }
        let err = FirmwareSetting::parse("2.0.2").unwrap_err();
        assert!(err.contains("\"auto\", \"2.0.1\", \"2.0.8\""), "{err}");
    }

    #[test]
    fn per_device_settings_override_the_bus() {
        let p = FirmwarePolicy::with_ids(
            FirmwareSetting::Auto,
            [
                ("9-10", FirmwareSetting::Fixed(Revision::V2_0_1)),
                ("3", FirmwareSetting::Fixed(Revision::V2_0_8)),
            ],
        )
        .unwrap();
        assert_eq!(p.for_id(1), FirmwareSetting::Auto);
        assert_eq!(p.for_id(3), FirmwareSetting::Fixed(Revision::V2_0_8));
        assert_eq!(p.for_id(10), FirmwareSetting::Fixed(Revision::V2_0_1));
        assert!(FirmwarePolicy::with_ids(
            FirmwareSetting::Auto,
            [("1-3", FirmwareSetting::Auto), ("2", FirmwareSetting::Auto)]
        )
        .unwrap_err()
        .contains("device 2 twice"));
    }
}
