//! The OpenAPI side of the config surface, built from the parameter table:
//! the schemas of `GET`/`PATCH …/config` (one property per offered row, its
//! range, step, unit and description from the row) and the JSON view of the
//! whole table served at `GET /api/v1/params` for the dashboard.

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::json;
use utoipa::openapi::schema::{
    AdditionalProperties, KnownFormat, Object, ObjectBuilder, Schema, SchemaFormat, SchemaType,
    Type,
};
use utoipa::openapi::{Ref, RefOr};
use utoipa::{PartialSchema, ToSchema};

use super::config_params::{api_params, ConfigPatch, Param, ParamValue, ParamValues};
use crate::protocol::params::{Guard, ParamRow, Revision, PARAMS};

/// Every parameter of a device, read from it now: the device's fields and
/// one [`ParamValue`] per offered parameter, by its key.
#[derive(Debug, Serialize)]
pub(crate) struct ConfigView {
    #[serde(flatten)]
    pub device: ConfigDevice,
    #[serde(flatten)]
    pub params: ParamValues,
}

/// The fields of a config read that are not parameters.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ConfigDevice {
    #[schema(example = "sim0")]
    pub bus: String,
    #[schema(example = 1)]
    pub id: u8,
    /// The protocol revision the device speaks (`2.0.1`, `2.0.8`; absent
    /// until known): what this surface offers it.
    #[schema(example = "2.0.1")]
    pub revision: Option<&'static str>,
    /// The device's baud from INFO_04 (absent if its level is unknown); change it on the bus.
    #[schema(example = 500000)]
    pub baud: Option<u32>,
    #[schema(example = 1)]
    pub baud_level: u8,
    #[schema(example = 3)]
    pub param_ver: u8,
    /// INFO_07's data bytes, hex (rev 2.0.8: the serial number, layout unpublished).
    #[schema(example = json!(null))]
    pub serial_number: Option<String>,
    /// Parameters a PATCH may write to this device that no published INFO
    /// block shows (rev 2.0.8's `drv_ot_c`, `spd_limit_rpm`, `sn`): written
    /// unverifiable, never shown here.
    #[schema(example = json!([]))]
    pub write_only: Vec<&'static str>,
    /// The raw data bytes of each block, hex (INFO_06 carries bytes whose
    /// layout is unpublished).
    #[schema(example = json!({"info03": "FF 0F 00 00 00 10 00 01", "info04": "02 01 03 00 10 11 69 03",
        "info05": "60 0B 58 02 46 02 90 01", "info06": "04 02 00 00 00 00 00 00"}))]
    pub raw: BTreeMap<String, String>,
}

impl PartialSchema for ConfigView {
    fn schema() -> RefOr<Schema> {
        let mut obj = match ConfigDevice::schema() {
            RefOr::T(Schema::Object(obj)) => obj,
            _ => Object::new(),
        };
        obj.description = Some("Every parameter of a device, read from it now.".into());
        // Write-only parameters (rev 2.0.8's) are never shown.
        for p in api_params().filter(|p| p.read_back.is_some()) {
            let value = RefOr::Ref(Ref::from_schema_name(ParamValue::name()));
            obj.properties.insert(p.key.into(), value);
            obj.required.push(p.key.into());
        }
        RefOr::T(Schema::Object(obj))
    }
}

impl ToSchema for ConfigView {
    fn schemas(schemas: &mut Vec<(String, RefOr<Schema>)>) {
        schemas.push((ParamValue::name().into(), ParamValue::schema()));
    }
}

// `example` (not 3.1's `examples`) like every derived schema of the document.
#[allow(deprecated)]
impl PartialSchema for ConfigPatch {
    fn schema() -> RefOr<Schema> {
        let mut b = ObjectBuilder::new()
            .schema_type(Type::Object)
            .description(Some(
                "Any subset of the writable parameters, in physical units. Written to RAM \
                 and verified by read-back; `POST .../config/persist` keeps them over a power cycle.",
            ))
            .additional_properties(Some(AdditionalProperties::<Schema>::FreeForm(false)))
            .example(Some(
                json!({"pos_kp": 1.25, "max_current_a": 2.0, "burst_plus_ms": 100.0}),
            ));
        for p in api_params() {
            b = b.property(p.key, patch_property(p));
        }
        b.into()
    }
}

impl ToSchema for ConfigPatch {}

/// One optional number of a patch: range, step and example from the row.
#[allow(deprecated)]
fn patch_property(p: Param) -> ObjectBuilder {
    let (min, max) = p.physical_range();
    ObjectBuilder::new()
        .schema_type(SchemaType::from_iter([Type::Number, Type::Null]))
        .format(Some(SchemaFormat::KnownFormat(KnownFormat::Double)))
        .description(Some(describe(p)))
        .minimum(Some(min))
        .maximum(Some(max))
        .multiple_of(p.scale.step())
        .example(Some(json!(round4(p.physical(p.default)))))
}

/// The factory value as an example a person would type (0.7498, not 0.74983977…).
fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

/// "Maximum output current, 0..=5.625 A (index 18)."
fn describe(p: &ParamRow) -> String {
    let (min, max) = p.physical_range();
    let unit = match p.unit() {
        "" => String::new(),
        u => format!(" {u}"),
    };
    let step = match p.scale.step() {
        Some(s) if s > 1.0 => format!(", multiples of {s}{unit}"),
        _ => String::new(),
    };
    let revision = if p.since > Revision::V2_0_1 {
        format!(
            " Rev {} firmware only (422 for other devices); write-only: no published \
             INFO block shows it, so the write is reported `unverifiable`.",
            p.since.as_str()
        )
    } else {
        String::new()
    };
    format!(
        "{}, {min}..={max}{unit}{step} (index {}).{revision}",
        p.doc, p.index
    )
}

/// The parameter table as JSON (`GET /api/v1/params`).
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ParamTable {
    /// The vendor document revision the table is read from; rows carry their own (`since`).
    #[schema(example = "2.0.1")]
    pub protocol: &'static str,
    /// One row per config index of SPEC §4.3 (the INFO reads included), by index.
    pub params: Vec<ParamInfo>,
}

/// One row of the parameter table.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ParamInfo {
    #[schema(example = 18)]
    pub index: u8,
    /// The vendor's name without `CONFIG_`.
    #[schema(example = "MAX_CUR")]
    pub name: &'static str,
    /// The REST field of an `api` row (and the simulator's storage key).
    #[schema(example = "max_current_a")]
    pub key: &'static str,
    /// `read` (asks for an INFO block) or `write`.
    #[schema(example = "write")]
    pub access: &'static str,
    /// `none`, `u8` or `u16`.
    #[schema(example = "u16")]
    pub raw_type: &'static str,
    /// How raw maps to physical: `plain`, `q12`, `q15_gain`, `q15_current`, `ms`,
    /// `x25ms`, `celsius`, `q15_speed`, `id_q7`, `baud_level`, `mode`.
    #[schema(example = "q15_current")]
    pub scale: &'static str,
    #[schema(example = "A")]
    pub unit: &'static str,
    #[schema(example = 0)]
    pub raw_min: u16,
    #[schema(example = 32767)]
    pub raw_max: u16,
    /// Physical range.
    #[schema(example = 0.0)]
    pub min: f64,
    #[schema(example = 5.625)]
    pub max: f64,
    /// Physical values must be multiples of this (absent: rounded to the nearest step).
    pub step: Option<f64>,
    /// `none`, `res` or `info`.
    #[schema(example = "none")]
    pub reply: &'static str,
    /// Where an INFO block shows the value (how a write is verified).
    pub read_back: Option<ReadBackInfo>,
    /// `ram` (kept after WRITE_FLASH), `flash` (stored at once), `volatile` (never saved), `none`.
    #[schema(example = "ram")]
    pub storage: &'static str,
    /// Why the generic write path refuses it (routed through another operation, or dangerous).
    pub guard: Option<&'static str>,
    /// Offered by `GET`/`PATCH …/config`.
    #[schema(example = true)]
    pub api: bool,
    /// Factory value, raw and physical.
    #[schema(example = 4368)]
    pub default_raw: u16,
    #[schema(example = 0.7498)]
    pub default: f64,
    /// Protocol revision that introduced the row.
    #[schema(example = "2.0.1")]
    pub since: &'static str,
    #[schema(example = "Maximum output current")]
    pub description: &'static str,
}

/// A read-back field: which block, where.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ReadBackInfo {
    /// The vendor name of the read (`INFO_04_R`).
    #[schema(example = "INFO_04_R")]
    pub block: &'static str,
    #[schema(example = 17)]
    pub block_index: u8,
    /// Byte offset in the block's 8 data bytes.
    #[schema(example = 4)]
    pub offset: usize,
    #[schema(example = "u16")]
    pub width: &'static str,
}

impl ParamTable {
    pub(crate) fn new() -> Self {
        Self {
            protocol: "2.0.1",
            params: PARAMS.iter().map(ParamInfo::new).collect(),
        }
    }
}

impl Default for ParamTable {
    fn default() -> Self {
        Self::new()
    }
}

impl ParamInfo {
    fn new(r: &'static ParamRow) -> Self {
        let (min, max) = r.physical_range();
        Self {
            index: r.index,
            name: r.name,
            key: r.key,
            access: r.access.as_str(),
            raw_type: r.raw.as_str(),
            scale: r.scale.as_str(),
            unit: r.unit(),
            raw_min: r.range.0,
            raw_max: r.range.1,
            min,
            max,
            step: r.scale.step(),
            reply: r.reply.as_str(),
            read_back: r.read_back.map(|f| ReadBackInfo {
                block: crate::protocol::params::name_of(f.block.index()),
                block_index: f.block.index(),
                offset: f.at,
                width: f.width.as_str(),
            }),
            storage: r.storage.as_str(),
            guard: match r.guard {
                Guard::None => None,
                Guard::Routed(why) | Guard::Dangerous(why) => Some(why),
            },
            api: r.api,
            default_raw: r.default,
            default: r.physical(r.default),
            since: r.since.as_str(),
            description: r.doc,
        }
    }
}
