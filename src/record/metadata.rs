//! The recording's MCAP Metadata record `jointd`: what a reader needs to
//! interpret the channels without the daemon at hand — the jointd version,
//! and every joint recorded: its bus and id, its name and hand, the firmware
//! it reported, and its calibration (the joint frame of `position_deg` and
//! of the joint states).
//!
//! MCAP metadata maps strings to strings: `jointd_version` is the version,
//! `joints` a JSON array of [`JointInfo`] (bus, then id order).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::hands::Calibration;

/// The Metadata record's name.
pub const NAME: &str = "jointd";

/// One joint as the recording knew it when it started.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointInfo {
    pub bus: String,
    pub id: u8,
    /// The name the joint states carry (a hand's joint name, a `[[joint]]`
    /// name, else `BUS_ID`).
    pub name: String,
    /// The hand it belongs to, if any.
    pub hand: Option<String>,
    /// Online when the recording started.
    pub online: bool,
    /// The firmware version it reported in INFO_01 (`soft_ver`), if it has.
    pub firmware: Option<String>,
    /// The protocol revision the daemon speaks to it (`2.0.1`, `2.0.8`), once known.
    pub protocol_revision: Option<String>,
    pub calibration: CalibrationInfo,
}

/// A joint's calibration: joint angle = (device angle − offset), negated
/// when flipped; `range_deg` the usable range in joint degrees.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationInfo {
    pub offset_deg: f64,
    pub flip: bool,
    pub range_deg: Option<[f64; 2]>,
}

impl From<&Calibration> for CalibrationInfo {
    fn from(c: &Calibration) -> Self {
        Self {
            offset_deg: c.offset_deg,
            flip: c.flip,
            range_deg: c.range_deg.map(|(lo, hi)| [lo, hi]),
        }
    }
}

/// The record's key/value map for `joints`.
pub fn record(joints: &[JointInfo]) -> BTreeMap<String, String> {
    let mut sorted = joints.to_vec();
    sorted.sort_by(|a, b| (&a.bus, a.id).cmp(&(&b.bus, b.id)));
    BTreeMap::from([
        (
            "jointd_version".to_owned(),
            env!("CARGO_PKG_VERSION").to_owned(),
        ),
        (
            "joints".to_owned(),
            serde_json::to_string(&sorted).unwrap_or_else(|_| "[]".to_owned()),
        ),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_joints_are_a_json_array_in_bus_then_id_order() {
        let joint = |bus: &str, id| JointInfo {
            bus: bus.to_owned(),
            id,
            name: format!("{bus}_{id}"),
            hand: None,
            online: true,
            firmware: Some("2.0.1".to_owned()),
            protocol_revision: None,
            calibration: (&Calibration::IDENTITY).into(),
        };
        let map = record(&[joint("b", 1), joint("a", 2), joint("a", 1)]);
        assert_eq!(map["jointd_version"], env!("CARGO_PKG_VERSION"));
        let joints: serde_json::Value = serde_json::from_str(&map["joints"]).unwrap();
        let order: Vec<_> = joints
            .as_array()
            .unwrap()
            .iter()
            .map(|j| j["name"].as_str().unwrap().to_owned())
            .collect();
        assert_eq!(order, ["a_1", "a_2", "b_1"]);
        assert_eq!(
            joints[0]["calibration"],
            serde_json::json!({"offset_deg": 0.0, "flip": false, "range_deg": null})
        );
    }
}
