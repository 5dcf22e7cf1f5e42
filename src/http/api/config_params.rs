//! The writable parameters of the REST config surface: the parameter
//! table's `api` rows by their `key`, physical ↔ raw through each row's
//! scale, and where each value sits in the INFO blocks (the row's read-back
//! field). Nothing here lists parameters: a row added to the table appears
//! in `GET`/`PATCH …/config` and in their OpenAPI schemas
//! ([`super::config_schema`]).

use std::fmt;
use std::sync::OnceLock;

use serde::de::{self, MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use utoipa::ToSchema;

use crate::bus::handle::DeviceState;
use crate::control::revision::require_revision;
use crate::http::error::{ApiError, ApiResult};
use crate::http::telemetry::revision_of;
use crate::protocol::params::{self, ParamRow, Revision};
use crate::protocol::units::UnitError;
use crate::protocol::{ConfigParam, InfoBlock};

/// One writable parameter: a row of the table the REST surface offers.
pub(crate) type Param = &'static ParamRow;

/// The parameters `GET`/`PATCH …/config` offer, in table order.
pub(crate) fn api_params() -> impl Iterator<Item = Param> {
    params::api_rows()
}

/// The REST names of [`api_params`] (serde's list of expected fields).
pub(crate) fn api_keys() -> &'static [&'static str] {
    static KEYS: OnceLock<Vec<&'static str>> = OnceLock::new();
    KEYS.get_or_init(|| api_params().map(|p| p.key).collect())
}

/// The INFO blocks a config read needs: INFO_04 (baud, parameter version)
/// and every block an offered parameter is read back from, in SPEC order.
pub(crate) fn blocks_to_read() -> Vec<InfoBlock> {
    InfoBlock::ALL
        .into_iter()
        .filter(|b| *b == InfoBlock::Info04 || api_params().any(|p| read_from(p) == Some(*b)))
        .collect()
}

fn read_from(p: Param) -> Option<InfoBlock> {
    p.read_back.map(|f| f.block)
}

/// The data bytes of the INFO blocks read from a device.
#[derive(Debug, Clone, Default)]
pub(crate) struct Blocks(pub Vec<(InfoBlock, [u8; 8])>);

impl Blocks {
    pub(crate) fn data(&self, block: InfoBlock) -> Option<&[u8; 8]> {
        self.0.iter().find(|(b, _)| *b == block).map(|(_, d)| d)
    }

    /// The raw value of a parameter, from its read-back field.
    pub(crate) fn raw_of(&self, p: Param) -> Option<u16> {
        let field = p.read_back?;
        self.data(field.block).map(|d| field.read(d))
    }
}

/// Physical → the typed write, range-checked (422 naming field and range).
pub(crate) fn to_config(p: Param, value: f64) -> ApiResult<ConfigParam> {
    let raw = p.to_raw(value).map_err(|e| unit_error(p, e))?;
    ConfigParam::from_index_value(p.index, raw).map_err(|e| ApiError::invalid(p.key, e.to_string()))
}

/// Whether a device of `revision` has the parameter (an unknown revision:
/// only what every revision has).
pub(crate) fn offered(p: Param, revision: Option<Revision>) -> bool {
    revision.unwrap_or(Revision::V2_0_1) >= p.since
}

/// 422 for a parameter the device's firmware does not have; 409 while its
/// revision is not known yet (asked when it is first heard).
pub(crate) fn check_offered(p: Param, id: u8, dev: &DeviceState) -> ApiResult<()> {
    if offered(p, revision_of(dev)) {
        return Ok(());
    }
    let what = format!("{} (index {})", p.key, p.index);
    Ok(require_revision(p.key, &what, p.since, id, dev)?)
}

/// A unit error as a 422; whole-number rows say so in words.
fn unit_error(p: Param, e: UnitError) -> ApiError {
    match e {
        UnitError::NotMultiple { value, step: 1, .. } => {
            let (min, max) = p.physical_range();
            ApiError::invalid(
                p.key,
                format!("{} = {value} must be a whole number {min}..={max}", p.key),
            )
        }
        e => ApiError::from_unit(p.key, e),
    }
}

/// A parameter's value in physical units with the raw value beside it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub(crate) struct ParamValue {
    #[schema(example = 0.5)]
    pub value: f64,
    #[schema(example = 2913)]
    pub raw: u16,
    /// `A`, `ms`, or empty for gains and levels.
    #[schema(example = "A")]
    pub unit: &'static str,
    /// The config index a write uses.
    #[schema(example = 18)]
    pub index: u8,
}

impl ParamValue {
    pub(crate) fn new(p: Param, raw: u16) -> Self {
        Self {
            value: p.physical(raw),
            raw,
            unit: p.unit(),
            index: p.index,
        }
    }
}

/// Offered parameters by key, serialized as JSON fields in table order.
#[derive(Debug, Clone, Default)]
pub(crate) struct ParamValues(pub Vec<(&'static str, ParamValue)>);

impl ParamValues {
    /// Every offered parameter the blocks show.
    pub(crate) fn from_blocks(blocks: &Blocks) -> Self {
        let values = api_params()
            .filter_map(|p| blocks.raw_of(p).map(|raw| (p.key, ParamValue::new(p, raw))))
            .collect();
        Self(values)
    }
}

impl Serialize for ParamValues {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (key, value) in &self.0 {
            map.serialize_entry(key, value)?;
        }
        map.end()
    }
}

/// Any subset of the offered parameters, in physical units (`{"pos_kp": 1.25}`).
/// Written to RAM and verified by read-back; `POST .../config/persist` keeps
/// them over a power cycle. Unknown fields are refused; `null` means "not given".
#[derive(Debug, Clone, Default)]
pub(crate) struct ConfigPatch(Vec<(Param, f64)>);

impl ConfigPatch {
    /// The parameters given, in table order (gains, smoothing, currents, protection, burst).
    pub(crate) fn entries(&self) -> Vec<(Param, f64)> {
        let mut all = self.0.clone();
        all.sort_by_key(|(p, _)| p.index);
        all
    }
}

impl<'de> Deserialize<'de> for ConfigPatch {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(PatchVisitor)
    }
}

struct PatchVisitor;

impl<'de> Visitor<'de> for PatchVisitor {
    type Value = ConfigPatch;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object of parameter names and numbers")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<ConfigPatch, A::Error> {
        let mut entries: Vec<(Param, f64)> = Vec::new();
        while let Some(key) = map.next_key::<String>()? {
            let param = api_params()
                .find(|p| p.key == key)
                .ok_or_else(|| de::Error::unknown_field(&key, api_keys()))?;
            if entries.iter().any(|(p, _)| p.key == param.key) {
                return Err(de::Error::duplicate_field(param.key));
            }
            if let Some(value) = map.next_value::<Option<f64>>()? {
                entries.push((param, value));
            }
        }
        Ok(ConfigPatch(entries))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::params::{by_key, index};

    fn p(key: &str) -> Param {
        by_key(key).unwrap()
    }

    #[test]
    fn physical_values_round_trip_through_raw() {
        let cases = [
            ("pos_kp", 1.25),
            ("spd_ki", 0.5),
            ("lpf_level", 3.0),
            ("max_current_a", 2.0),
            ("protect_delay_ms", 600.0),
            ("burst_plus_ms", 100.0),
        ];
        for (key, v) in cases {
            let param = p(key);
            let (idx, raw) = to_config(param, v).unwrap().index_value();
            assert_eq!(idx, param.index, "{key}");
            assert!(
                (param.physical(raw) - v).abs() < 1e-3,
                "{key}: {v} -> {raw}"
            );
        }
    }

    #[test]
    fn out_of_range_and_fractional_values_are_422() {
        for (key, v) in [
            ("lpf_level", 6.0),
            ("lpf_level", 1.5),
            ("max_current_a", 6.0),
            ("burst_cold_ms", 30.0),
            ("pos_kd", -0.1),
            ("spd_ki", f64::INFINITY),
        ] {
            let err = to_config(p(key), v).unwrap_err();
            assert_eq!(err.problem.status, 422);
            assert_eq!(err.problem.field.as_deref(), Some(key));
        }
    }

    #[test]
    fn a_patch_refuses_unknown_fields_and_skips_nulls() {
        let patch: ConfigPatch =
            serde_json::from_str(r#"{"max_current_a": 2.0, "pos_kp": 1.0, "spd_kp": null}"#)
                .unwrap();
        let keys: Vec<_> = patch.entries().iter().map(|(p, _)| p.key).collect();
        assert_eq!(keys, ["pos_kp", "max_current_a"]);
        let err = serde_json::from_str::<ConfigPatch>(r#"{"max_cur": 2.0}"#).unwrap_err();
        assert!(err.to_string().contains("unknown field `max_cur`"), "{err}");
        assert!(serde_json::from_str::<ConfigPatch>(r#"{"pos_kp": "1"}"#).is_err());
    }

    #[test]
    fn reads_cover_every_block_an_offered_parameter_lives_in() {
        let blocks = blocks_to_read();
        assert_eq!(
            blocks,
            [
                InfoBlock::Info03,
                InfoBlock::Info04,
                InfoBlock::Info05,
                InfoBlock::Info06
            ]
        );
        let data = Blocks(
            blocks
                .iter()
                .map(|b| (*b, [1, 0, 2, 0, 3, 0, 4, 0]))
                .collect(),
        );
        let values = ParamValues::from_blocks(&data);
        // Every offered parameter with a read-back shows; write-only ones cannot.
        let readable = api_params().filter(|p| p.read_back.is_some()).count();
        assert_eq!(values.0.len(), readable);
        let lpf = by_key("lpf_level").map(|r| r.index);
        assert_eq!(lpf, Some(index::POS_LPF_LV));
    }
}
