//! Frames ↔ JSON, with the field names of `meaning` in `vectors.json`.
//!
//! Decoding gives every raw field and its physical value side by side, plus
//! the raw data bytes; encoding accepts either a raw field or its physical
//! twin (`pos_ref_raw` or `pos_deg`), and when both are given they must agree.
//! The CLI, the tests and (later) the API's raw frame view share this mapping.

use serde_json::{json, Map, Value};
use thiserror::Error;

use super::command::CAN_ID_VENDOR_ENABLE_ALL;
use super::params::{self, Access, ParamRow, Scale};
use super::status::{active_fault, fault_history, fault_name, fsm_name};
use super::units::{self, FirmwareVersion};
use super::{
    BaudLevel, BroadcastEnable, BroadcastPos, BroadcastSpd, Command, Config, ConfigParam, Control,
    ControlOp, CrcCoverage, CtrlMode, Frame, Group, Jog, JogDir, Message, ProtocolError, Reply,
    ReplyBody, VendorCommand,
};

#[derive(Debug, Error)]
pub enum FrameJsonError {
    #[error("not valid JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("expected a JSON object describing one frame")]
    NotObject,
    #[error("missing field `{0}`")]
    Missing(&'static str),
    #[error("field `{field}`: {why}")]
    BadValue { field: String, why: String },
    #[error("unknown field `{field}` for kind `{kind}`; allowed: {allowed}")]
    UnknownField {
        field: String,
        kind: String,
        allowed: String,
    },
    #[error(
        "`{raw}` and `{physical}` disagree: {physical} gives raw {from_physical}, {raw} is {given}"
    )]
    Mismatch {
        raw: &'static str,
        physical: &'static str,
        from_physical: i64,
        given: i64,
    },
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
}

impl From<units::UnitError> for FrameJsonError {
    fn from(e: units::UnitError) -> Self {
        FrameJsonError::Protocol(e.into())
    }
}

/// Bytes as spaced upper-case hex (`55 AA 00 14`), as captures and the vectors write them.
pub fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The JSON description of a decoded frame. A frame with a valid CRC that is
/// neither a command nor a reply gets `kind: "invalid"` and the reason.
pub fn frame_to_json(frame: &Frame) -> Value {
    let (mut obj, raw) = match Message::from_frame(frame) {
        Ok(Message::Reply(r)) => (reply_json(&r), r.data.to_vec()),
        Ok(Message::Command(c)) => (command_json(&c), payload(frame)),
        Err(e) => (invalid_json(frame, &e), payload(frame)),
    };
    obj.insert("raw".into(), Value::String(hex(&raw)));
    Value::Object(obj)
}

fn payload(frame: &Frame) -> Vec<u8> {
    match frame {
        Frame::Standard(f) => f.data.to_vec(),
        Frame::Broadcast(b) => b.values.to_vec(),
    }
}

fn invalid_json(frame: &Frame, e: &ProtocolError) -> Map<String, Value> {
    let mut m = obj(json!({"kind": "invalid", "error": e.to_string()}));
    if let Frame::Standard(f) = frame {
        m.insert("can_id".into(), json!(f.can_id));
    }
    m
}

fn obj(v: Value) -> Map<String, Value> {
    match v {
        Value::Object(m) => m,
        _ => Map::new(),
    }
}

fn extend(m: &mut Map<String, Value>, more: Value) {
    m.extend(obj(more));
}

/// A reply's fields; speeds are given for both firmware speed bases since a
/// reply alone does not say which firmware sent it.
pub fn reply_json(r: &Reply) -> Map<String, Value> {
    let mut m = obj(json!({"kind": "reply", "dev_id": r.dev_id, "index": r.index}));
    let body = match r.body() {
        ReplyBody::Info01(i) => json!({
            "fsm": i.fsm, "fsm_name": fsm_name(i.fsm),
            "err_code": i.err_code, "fault": fault_name(active_fault(i.err_code)),
            "fault_history": fault_name(fault_history(i.err_code)),
            "soft_ver": i.soft_ver, "firmware": i.firmware().dotted(),
            "temp_raw": i.temp_raw, "temp_c": i.temp_c(),
            "angle_raw": i.angle, "angle_deg": i.angle_deg(),
            "vbus_raw": i.vbus, "vbus_v": i.vbus_v(),
        }),
        ReplyBody::Info02(i) => json!({
            "d_cur_raw": i.d_cur, "q_cur_raw": i.q_cur, "speed_raw": i.speed, "angle_raw": i.angle,
            "d_cur_a": units::current_a(i.d_cur), "q_cur_a": units::current_a(i.q_cur),
            "speed_rpm_fw124": i.speed_rpm(FirmwareVersion::SPEED_BASE_50K),
            "speed_rpm_pre124": i.speed_rpm(FirmwareVersion(0)),
            "angle_deg": i.angle_deg(),
        }),
        ReplyBody::Info03(g) => json!({
            "pos_kp_raw": g.pos_kp, "pos_kd_raw": g.pos_kd, "spd_kp_raw": g.spd_kp, "spd_ki_raw": g.spd_ki,
            "pos_kp": units::gain_q12(g.pos_kp), "pos_kd": units::gain_q12(g.pos_kd),
            "spd_kp": units::gain_q12(g.spd_kp), "spd_ki": units::gain_ki(g.spd_ki),
        }),
        ReplyBody::Info04(i) => json!({
            "lpf_level": i.lpf_level, "baud_level": i.baud_level,
            "baud": BaudLevel::from_raw(i.baud_level).map(BaudLevel::baud),
            "param_ver": i.param_ver,
            "max_current_raw": i.max_current, "protect_limit_raw": i.protect_limit,
            "max_current_a": units::current_limit_a(i.max_current),
            "protect_limit_a": units::current_limit_a(i.protect_limit),
        }),
        ReplyBody::Info05(i) => json!({
            "protect_cur_lv1_raw": i.protect_cur_lv1, "protect_delay_lv1_ms": i.protect_delay_lv1_ms,
            "recv_cur_raw": i.recv_cur, "recover_delay_ms": i.recover_delay_ms,
            "protect_cur_lv1_a": units::current_limit_a(i.protect_cur_lv1),
            "recv_cur_a": units::current_limit_a(i.recv_cur),
        }),
        ReplyBody::Info06(i) => json!({
            "cold_dt_raw": i.cold_dt, "cold_ms": units::burst_ms(i.cold_dt),
            "plus_t_raw": i.plus_t, "plus_ms": units::burst_ms(i.plus_t),
        }),
        ReplyBody::Info07(_) | ReplyBody::Unknown { .. } => json!({}),
        ReplyBody::Res { code, .. } => json!({"res": code, "ok": code == 1}),
    };
    extend(&mut m, body);
    m
}

fn command_json(c: &Command) -> Map<String, Value> {
    match c {
        Command::Control(c) => obj(json!({
            "kind": "control", "dev_id": c.dev_id, "en": c.op as u8, "op": c.op.name(),
            "pos_ref_raw": c.pos_ref, "pos_deg": units::angle_deg(c.pos_ref),
            "spd_ref_raw": c.spd_ref,
            "spd_rpm": units::speed_rpm(c.spd_ref, FirmwareVersion::SPEED_BASE_50K),
            "cur_ref_raw": c.cur_ref,
        })),
        Command::Jog(j) => obj(json!({"kind": "jog", "dev_id": j.dev_id, "dir": dir_name(j.dir)})),
        Command::Config(c) => config_json(c),
        Command::BroadcastPos(b) => obj(json!({
            "kind": "broadcast", "head2": head2(c), "group": group_name("pos", b.group),
            "values_raw": b.pos_ref,
            "values_deg": b.pos_ref.map(units::angle_deg),
        })),
        Command::BroadcastSpd(b) => obj(json!({
            "kind": "broadcast", "head2": head2(c), "group": group_name("spd", b.group),
            "values_raw": b.spd_ref,
            "values_rpm": b.spd_ref.map(|v| units::speed_rpm(v, FirmwareVersion::SPEED_BASE_50K)),
        })),
        Command::BroadcastEnableUnverified(b) => obj(json!({
            "kind": "broadcast", "head2": head2(c), "group": "enable 1-16",
            "values_raw": b.ops, "unverified": true, "crc": b.crc.describe(),
        })),
        Command::Vendor(v) => {
            let mut m = obj(json!({"kind": "vendor", "name": v.name(), "note": v.note()}));
            let fields = match v {
                VendorCommand::EnableAll { dev_id, op } => json!({
                    "can_id": CAN_ID_VENDOR_ENABLE_ALL, "dev_id": dev_id, "op_raw": op,
                    "op": match op { 1 => "enable", 0 | 2 => "disable", _ => "unknown" },
                }),
                VendorCommand::CurrentBroadcast { group, cur_ref } => json!({
                    "head2": head2(c), "group": group_name("cur", *group), "values_raw": cur_ref,
                }),
            };
            extend(&mut m, fields);
            m
        }
    }
}

fn head2(c: &Command) -> Option<u16> {
    match c.to_frame() {
        Frame::Broadcast(b) => Some(b.kind.head2()),
        Frame::Standard(_) => None,
    }
}

fn config_json(c: &Config) -> Map<String, Value> {
    let (idx, value) = c.param.index_value();
    let mut m = obj(json!({
        "kind": "config", "dev_id": c.dev_id, "index": idx, "name": index_name(idx), "value": value,
    }));
    if let Some((field, physical)) = params::by_index(idx).and_then(|row| physical_json(row, value))
    {
        m.insert(field.into(), physical);
    }
    m
}

/// The physical twin of a config value, named by the row's scale (`"amps"`).
/// Whole-step scales (ms, ids, bauds) print integers, the rest decimals.
fn physical_json(row: &ParamRow, value: u16) -> Option<(&'static str, Value)> {
    let field = row.scale.json_field()?;
    if row.access == Access::Read {
        return None;
    }
    let v = match row.scale {
        Scale::CtrlMode => json!(CtrlMode::from_raw(value as u8).map(CtrlMode::name)),
        s if s.is_whole() => json!(row.physical(value) as i64),
        _ => json!(row.physical(value)),
    };
    Some((field, v))
}

fn dir_name(d: JogDir) -> &'static str {
    match d {
        JogDir::None => "none",
        JogDir::Cw => "cw",
        JogDir::Ccw => "ccw",
    }
}

fn group_name(what: &str, g: Group) -> String {
    match g {
        Group::Low => format!("{what} 1-8"),
        Group::High => format!("{what} 9-16"),
    }
}

/// The vendor's name of a config index, without the `CONFIG_` prefix
/// (`"UNKNOWN"` for an index the parameter table has no row for).
pub fn index_name(idx: u8) -> &'static str {
    super::params::name_of(idx)
}

// ---------------------------------------------------------------- encoding

/// Reads the fields of one JSON object, remembering which were used so
/// unknown (mistyped) fields can be refused instead of silently ignored.
struct Fields<'a> {
    map: &'a Map<String, Value>,
    kind: &'a str,
}

impl<'a> Fields<'a> {
    fn int(&self, name: &'static str) -> Result<Option<i64>, FrameJsonError> {
        match self.map.get(name) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => v
                .as_i64()
                .map(Some)
                .ok_or_else(|| bad(name, "expected an integer")),
        }
    }

    fn num(&self, name: &'static str) -> Result<Option<f64>, FrameJsonError> {
        match self.map.get(name) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => v
                .as_f64()
                .map(Some)
                .ok_or_else(|| bad(name, "expected a number")),
        }
    }

    fn str_or_int(&self, name: &'static str) -> Option<&'a Value> {
        self.map.get(name)
    }

    fn check_known(&self, allowed: &[&str]) -> Result<(), FrameJsonError> {
        let always = ["kind", "raw", "name", "note", "op", "unverified"];
        for key in self.map.keys() {
            if !allowed.contains(&key.as_str()) && !always.contains(&key.as_str()) {
                return Err(FrameJsonError::UnknownField {
                    field: key.clone(),
                    kind: self.kind.to_string(),
                    allowed: allowed.join(", "),
                });
            }
        }
        Ok(())
    }
}

fn bad(field: &str, why: impl Into<String>) -> FrameJsonError {
    FrameJsonError::BadValue {
        field: field.to_string(),
        why: why.into(),
    }
}

fn in_range<T: TryFrom<i64>>(field: &'static str, v: i64, what: &str) -> Result<T, FrameJsonError> {
    T::try_from(v).map_err(|_| bad(field, format!("{v} does not fit {what}")))
}

/// A raw integer field or its physical twin; when both are given they must agree.
fn raw_or_physical(
    f: &Fields,
    raw: &'static str,
    physical: &'static str,
    convert: impl Fn(f64) -> Result<i64, FrameJsonError>,
) -> Result<Option<i64>, FrameJsonError> {
    let from_phys = f.num(physical)?.map(&convert).transpose()?;
    match (f.int(raw)?, from_phys) {
        (Some(given), Some(from_physical)) if given != from_physical => {
            Err(FrameJsonError::Mismatch {
                raw,
                physical,
                from_physical,
                given,
            })
        }
        (given, from_phys) => Ok(given.or(from_phys)),
    }
}

/// The host→device command a JSON object describes (`jointd frame encode`).
pub fn command_from_json(v: &Value) -> Result<Command, FrameJsonError> {
    let map = v.as_object().ok_or(FrameJsonError::NotObject)?;
    let kind = map
        .get("kind")
        .and_then(Value::as_str)
        .ok_or(FrameJsonError::Missing("kind"))?;
    let f = Fields { map, kind };
    match kind {
        "control" => control_from(&f),
        "jog" => jog_from(&f),
        "config" => config_from(&f),
        "broadcast" => broadcast_from(&f),
        other => Err(bad(
            "kind",
            format!("`{other}` is not a host command; use control, jog, config or broadcast"),
        )),
    }
}

fn dev_id(f: &Fields) -> Result<u8, FrameJsonError> {
    let id = f.int("dev_id")?.ok_or(FrameJsonError::Missing("dev_id"))?;
    let id: u8 = in_range("dev_id", id, "a device id (1..=159 or 255)")?;
    if !super::is_address(id) {
        return Err(ProtocolError::BadAddress(id).into());
    }
    Ok(id)
}

fn firmware(f: &Fields) -> Result<FirmwareVersion, FrameJsonError> {
    let v = f
        .int("soft_ver")?
        .unwrap_or(i64::from(FirmwareVersion::SPEED_BASE_50K.0));
    Ok(FirmwareVersion(in_range("soft_ver", v, "a u8")?))
}

fn control_from(f: &Fields) -> Result<Command, FrameJsonError> {
    f.check_known(&[
        "dev_id",
        "en",
        "pos_ref_raw",
        "pos_deg",
        "spd_ref_raw",
        "spd_rpm",
        "cur_ref_raw",
        "soft_ver",
    ])?;
    let dev_id = dev_id(f)?;
    let op = match f.str_or_int("en") {
        Some(Value::String(s)) if s == "enable" => ControlOp::Enable,
        Some(Value::String(s)) if s == "disable" => ControlOp::Disable,
        Some(Value::String(s)) if s == "set_ref" => ControlOp::SetRef,
        Some(v) if v.as_i64() == Some(1) => ControlOp::Enable,
        Some(v) if v.as_i64() == Some(2) => ControlOp::Disable,
        Some(v) if v.as_i64() == Some(3) => ControlOp::SetRef,
        Some(_) => {
            return Err(bad(
                "en",
                "1/\"enable\", 2/\"disable\" or 3/\"set_ref\" (jointd never sends 0: rev 2.0.8 reads it as set-ref, V2.0.1 as a no-op)",
            ))
        }
        None => return Err(FrameJsonError::Missing("en")),
    };
    let fw = firmware(f)?;
    let pos = raw_or_physical(f, "pos_ref_raw", "pos_deg", |d| {
        Ok(units::angle_to_raw(d)?.into())
    })?;
    let spd = raw_or_physical(f, "spd_ref_raw", "spd_rpm", |r| {
        Ok(units::speed_to_raw(r, fw)?.into())
    })?;
    if op == ControlOp::SetRef && (pos.is_none() || spd.is_none()) {
        // A missing target would move the joint to 0°: refuse rather than guess.
        return Err(bad(
            "en",
            "set_ref needs pos_ref_raw/pos_deg and spd_ref_raw/spd_rpm",
        ));
    }
    Ok(Command::Control(Control {
        dev_id,
        op,
        pos_ref: in_range("pos_ref_raw", pos.unwrap_or(0), "an i16")?,
        spd_ref: in_range("spd_ref_raw", spd.unwrap_or(0), "an i16")?,
        cur_ref: in_range("cur_ref_raw", f.int("cur_ref_raw")?.unwrap_or(0), "an i16")?,
    }))
}

fn jog_from(f: &Fields) -> Result<Command, FrameJsonError> {
    f.check_known(&["dev_id", "dir"])?;
    let dev_id = dev_id(f)?;
    let dir = match f.str_or_int("dir") {
        Some(Value::String(s)) if s == "cw" => JogDir::Cw,
        Some(Value::String(s)) if s == "ccw" => JogDir::Ccw,
        Some(Value::String(s)) if s == "none" => JogDir::None,
        Some(v) if v.as_i64() == Some(0) => JogDir::None,
        Some(v) if v.as_i64() == Some(1) => JogDir::Cw,
        Some(v) if v.as_i64() == Some(2) => JogDir::Ccw,
        Some(_) => return Err(bad("dir", "\"cw\" (+5°), \"ccw\" (−3°) or \"none\"")),
        None => return Err(FrameJsonError::Missing("dir")),
    };
    Ok(Command::Jog(Jog { dev_id, dir }))
}

fn config_from(f: &Fields) -> Result<Command, FrameJsonError> {
    let mut allowed = vec!["dev_id", "index", "value"];
    for field in params::PARAMS.iter().filter_map(|r| r.scale.json_field()) {
        if !allowed.contains(&field) {
            allowed.push(field);
        }
    }
    f.check_known(&allowed)?;
    let dev_id = dev_id(f)?;
    let idx = f.int("index")?.ok_or(FrameJsonError::Missing("index"))?;
    let idx: u8 = in_range("index", idx, "an index (0..=255)")?;
    let value = config_value(f, idx)?;
    let param = ConfigParam::from_index_value(idx, value)?;
    Ok(Command::Config(Config { dev_id, param }))
}

/// The raw value of a config command, from `value` or the physical field
/// the index's row names (`amps`, `gain`, `ms`, …).
fn config_value(f: &Fields, idx: u8) -> Result<u16, FrameJsonError> {
    let row = params::by_index(idx).filter(|r| r.access == Access::Write);
    let physical = match row.and_then(|r| r.scale.json_field().map(|field| (r, field))) {
        Some((row, _)) if row.scale == Scale::CtrlMode => mode_value(f)?,
        Some((row, field)) => raw_or_physical(f, "value", field, |v| Ok(row.to_raw(v)?.into()))?,
        None => f.int("value")?,
    };
    in_range("value", physical.unwrap_or(0), "a u16 (0..=65535)")
}

fn mode_value(f: &Fields) -> Result<Option<i64>, FrameJsonError> {
    let named = match f.map.get("mode").and_then(Value::as_str) {
        None => None,
        Some(name) => match CtrlMode::from_name(name) {
            Some(mode) => Some(mode as i64),
            None => {
                return Err(bad(
                    "mode",
                    "\"speed\", \"position\", \"current\" or \"none\"",
                ))
            }
        },
    };
    match (f.int("value")?, named) {
        (Some(given), Some(from_physical)) if given != from_physical => {
            Err(FrameJsonError::Mismatch {
                raw: "value",
                physical: "mode",
                from_physical,
                given,
            })
        }
        (given, named) => Ok(given.or(named)),
    }
}

fn broadcast_from(f: &Fields) -> Result<Command, FrameJsonError> {
    f.check_known(&[
        "head2",
        "group",
        "values_raw",
        "values_deg",
        "values_rpm",
        "soft_ver",
    ])?;
    let group = broadcast_group(f)?;
    match group.as_str() {
        "pos 1-8" | "pos 9-16" => {
            let g = if group == "pos 1-8" {
                Group::Low
            } else {
                Group::High
            };
            let pos_ref = values8(f, "values_deg", |d| Ok(units::angle_to_raw(d)?.into()))?;
            Ok(Command::BroadcastPos(BroadcastPos { group: g, pos_ref }))
        }
        "spd 1-8" | "spd 9-16" => {
            let g = if group == "spd 1-8" {
                Group::Low
            } else {
                Group::High
            };
            let fw = firmware(f)?;
            let spd_ref = values8(f, "values_rpm", |r| Ok(units::speed_to_raw(r, fw)?.into()))?;
            Ok(Command::BroadcastSpd(BroadcastSpd { group: g, spd_ref }))
        }
        _ => {
            let raw = int_list(f, "values_raw")?.ok_or(FrameJsonError::Missing("values_raw"))?;
            let ops: [u8; 16] = list_to_array(raw, "values_raw", "a u8")?;
            Ok(Command::BroadcastEnableUnverified(BroadcastEnable {
                ops,
                crc: CrcCoverage::Values,
            }))
        }
    }
}

/// The group name, from `group` or `head2` (they must agree when both are given).
fn broadcast_group(f: &Fields) -> Result<String, FrameJsonError> {
    const GROUPS: [(u16, &str); 5] = [
        (0xAB55, "pos 1-8"),
        (0xAC55, "pos 9-16"),
        (0xAD55, "spd 1-8"),
        (0xAE55, "spd 9-16"),
        (0xB155, "enable 1-16"),
    ];
    let by_head = f
        .int("head2")?
        .map(|h| {
            GROUPS
                .iter()
                .find(|(g, _)| i64::from(*g) == h)
                .map(|(_, n)| n.to_string())
                .ok_or_else(|| bad("head2", "one of 43861 (0xAB55), 44117, 44373, 44629, 45397"))
        })
        .transpose()?;
    let by_name = f
        .map
        .get("group")
        .and_then(Value::as_str)
        .map(str::to_string);
    if let Some(n) = &by_name {
        if !GROUPS.iter().any(|(_, g)| g == n) {
            return Err(bad(
                "group",
                "one of \"pos 1-8\", \"pos 9-16\", \"spd 1-8\", \"spd 9-16\", \"enable 1-16\"",
            ));
        }
    }
    match (by_head, by_name) {
        (Some(h), Some(n)) if h != n => {
            Err(bad("group", format!("`{n}` disagrees with head2 (`{h}`)")))
        }
        (Some(g), _) | (None, Some(g)) => Ok(g),
        (None, None) => Err(FrameJsonError::Missing("group")),
    }
}

fn int_list(f: &Fields, name: &'static str) -> Result<Option<Vec<i64>>, FrameJsonError> {
    match f.map.get(name) {
        None => Ok(None),
        Some(Value::Array(a)) => a
            .iter()
            .map(|v| v.as_i64().ok_or_else(|| bad(name, "expected integers")))
            .collect::<Result<_, _>>()
            .map(Some),
        Some(_) => Err(bad(name, "expected an array")),
    }
}

fn list_to_array<T: TryFrom<i64>, const N: usize>(
    list: Vec<i64>,
    field: &'static str,
    what: &str,
) -> Result<[T; N], FrameJsonError> {
    if list.len() != N {
        return Err(bad(
            field,
            format!("expected {N} values, got {}", list.len()),
        ));
    }
    let items = list
        .into_iter()
        .map(|v| in_range::<T>(field, v, what))
        .collect::<Result<Vec<T>, _>>()?;
    items
        .try_into()
        .map_err(|_| bad(field, format!("expected {N} values")))
}

/// Eight raw values from `values_raw` or the physical list; both must agree when given.
fn values8(
    f: &Fields,
    physical: &'static str,
    convert: impl Fn(f64) -> Result<i64, FrameJsonError>,
) -> Result<[i16; 8], FrameJsonError> {
    let raw = int_list(f, "values_raw")?;
    let phys = match f.map.get(physical) {
        None => None,
        Some(Value::Array(a)) => Some(
            a.iter()
                .map(|v| {
                    v.as_f64()
                        .ok_or_else(|| bad(physical, "expected numbers"))
                        .and_then(&convert)
                })
                .collect::<Result<Vec<i64>, _>>()?,
        ),
        Some(_) => return Err(bad(physical, "expected an array")),
    };
    let list = match (raw, phys) {
        (Some(r), Some(p)) if r != p => {
            return Err(bad(
                physical,
                format!("gives raw {p:?}, values_raw is {r:?}"),
            ))
        }
        (Some(r), _) => r,
        (None, Some(p)) => p,
        (None, None) => return Err(FrameJsonError::Missing("values_raw")),
    };
    list_to_array(list, "values_raw", "an i16")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::params::PARAMS;

    /// Every written value of every row survives decode → JSON → encode,
    /// through its physical twin alone (a field that is printed must also be
    /// taken on encode, SPD_LIMIT's `rpm` included).
    #[test]
    fn every_row_round_trips_through_its_physical_twin() {
        for row in PARAMS.iter().filter(|r| r.access == Access::Write) {
            let value = row.default.clamp(row.range.0, row.range.1);
            let Ok(param) = ConfigParam::from_index_value(row.index, value) else {
                panic!("{}: default {value} refused", row.name)
            };
            let cmd = Command::Config(Config { dev_id: 3, param });
            let mut json = frame_to_json(&cmd.to_frame());
            assert_eq!(json["name"], row.name);
            if row.scale.json_field().is_some() {
                json.as_object_mut().map(|m| m.remove("value"));
            }
            let back = command_from_json(&json).unwrap_or_else(|e| panic!("{}: {e}", row.name));
            assert_eq!(back, cmd, "{}", row.name);
        }
    }
}
