//! The messages of `jointd.ws.v1` (docs/websocket.md), parsed strictly:
//! an unknown type or field is an error naming it, never silently ignored.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::control::grasp::{GraspRequest, ReleaseRequest};
use crate::control::moves::MoveRequest;
use crate::control::teleop::WatchdogPolicy;
use crate::http::scope::{Needs, Scope};

pub(crate) use super::replies::{BusInfo, ErrorCode, EventBody, Field, Limits, ServerMessage};

/// Name and version of this protocol, sent in `welcome`.
pub(crate) const PROTOCOL: &str = "jointd.ws.v1";

/// The client message types, as errors list them.
const TYPES: &str = "subscribe, unsubscribe, setpoints, watchdog, ping, move, grasp, \
     grasp_release, grasp_stop, enable, disable, estop";

/// A message from the client.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ClientMessage {
    Subscribe(Subscribe),
    Unsubscribe {
        seq: Option<u64>,
    },
    Setpoints(SetpointBatch),
    Watchdog(WatchdogRequest),
    Ping {
        seq: Option<u64>,
    },
    /// Start a move (the body of `POST /api/v1/moves`).
    Move {
        seq: Option<u64>,
        request: MoveRequest,
    },
    /// Start a grasp of `hand` (the body of `POST /api/v1/hands/{hand}/grasp`).
    Grasp {
        seq: Option<u64>,
        hand: String,
        request: GraspRequest,
    },
    /// Release grasp `id` (the body of `POST /api/v1/grasps/{id}/release`).
    GraspRelease {
        seq: Option<u64>,
        id: u64,
        request: ReleaseRequest,
    },
    /// Stop grasp `id`.
    GraspStop {
        seq: Option<u64>,
        id: u64,
    },
    /// Enable joints of a bus (the body of `POST /api/v1/buses/{bus}/control/enable`).
    Enable(JointsOfBus),
    /// Disable joints of a bus.
    Disable(JointsOfBus),
    /// The e-stop of one bus, or of every bus (`POST /api/v1/estop`).
    Estop(EstopRequest),
}

impl ClientMessage {
    /// Its `type`, as the client wrote it.
    pub(crate) fn kind(&self) -> &'static str {
        match self {
            Self::Subscribe(_) => "subscribe",
            Self::Unsubscribe { .. } => "unsubscribe",
            Self::Setpoints(_) => "setpoints",
            Self::Watchdog(_) => "watchdog",
            Self::Ping { .. } => "ping",
            Self::Move { .. } => "move",
            Self::Grasp { .. } => "grasp",
            Self::GraspRelease { .. } => "grasp_release",
            Self::GraspStop { .. } => "grasp_stop",
            Self::Enable(_) => "enable",
            Self::Disable(_) => "disable",
            Self::Estop(_) => "estop",
        }
    }

    /// Its `seq`, quoted by the answer.
    pub(crate) fn seq(&self) -> Option<u64> {
        match self {
            Self::Subscribe(s) => s.seq,
            Self::Setpoints(b) => b.seq,
            Self::Watchdog(w) => w.seq,
            Self::Unsubscribe { seq }
            | Self::Ping { seq }
            | Self::Move { seq, .. }
            | Self::Grasp { seq, .. }
            | Self::GraspRelease { seq, .. }
            | Self::GraspStop { seq, .. } => *seq,
            Self::Enable(j) | Self::Disable(j) => j.seq,
            Self::Estop(e) => e.seq,
        }
    }

    /// What it needs of the connection's token, as REST's routes do: to
    /// look, `read`; to move (and to arm a watchdog), `operate`; to stop,
    /// any token.
    pub(crate) fn needs(&self) -> Needs {
        match self {
            Self::Subscribe(_) | Self::Unsubscribe { .. } | Self::Ping { .. } => {
                Needs::Scope(Scope::Read)
            }
            Self::Estop(_) => Needs::AnyToken,
            Self::Setpoints(_)
            | Self::Watchdog(_)
            | Self::Move { .. }
            | Self::Grasp { .. }
            | Self::GraspRelease { .. }
            | Self::GraspStop { .. }
            | Self::Enable(_)
            | Self::Disable(_) => Needs::Scope(Scope::Operate),
        }
    }
}

/// The joints of a bus an `enable` or `disable` addresses; `ids` left
/// out: every joint of the bus.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct JointsOfBus {
    pub seq: Option<u64>,
    pub bus: String,
    pub ids: Option<Vec<i64>>,
}

/// The bus an `estop` stops; `bus` left out: every bus.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EstopRequest {
    pub seq: Option<u64>,
    pub bus: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Subscribe {
    pub seq: Option<u64>,
    /// Bus names; all buses when absent.
    pub buses: Option<Vec<String>>,
    /// Device ids; all devices when absent.
    pub devices: Option<Vec<i64>>,
    /// Joint fields; all when absent.
    pub fields: Option<Vec<Field>>,
    /// Telemetry messages per second.
    pub rate_hz: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SetpointBatch {
    pub seq: Option<u64>,
    /// Answer with an `ack` once every target is on the wire.
    #[serde(default)]
    pub ack: bool,
    /// Begin new streams for these joints (after one ended).
    #[serde(default)]
    pub restart: bool,
    pub targets: Vec<TargetItem>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TargetItem {
    /// Optional when the daemon has exactly one bus.
    pub bus: Option<String>,
    /// The joint by id on `bus`; or by `hand` and `joint` name instead.
    pub id: Option<i64>,
    pub hand: Option<String>,
    pub joint: Option<String>,
    pub position_deg: Option<f64>,
    pub speed_dps: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct WatchdogRequest {
    pub seq: Option<u64>,
    /// 0 disarms.
    pub hold_timeout_ms: u64,
    #[serde(default = "default_policy")]
    pub policy: WatchdogPolicy,
}

fn default_policy() -> WatchdogPolicy {
    WatchdogPolicy::Hold
}

#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
struct SeqOnly {
    seq: Option<u64>,
}

/// Why a client message could not be read.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ParseError {
    pub code: ErrorCode,
    pub message: String,
    /// The `seq` of the message, when it could be read.
    pub seq: Option<u64>,
}

/// A `setpoints` message read straight from its text: a teleop client
/// sends one every millisecond, spared here the detour through a `Value`.
/// It takes what [`parse`]'s generic path takes, no more; anything it
/// refuses goes that way, whose errors say what was wrong.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SetpointsText<'a> {
    /// Borrowed: only a plain string (an escaped one goes the long way).
    #[serde(rename = "type", borrow)]
    kind: &'a str,
    seq: Option<u64>,
    #[serde(default)]
    ack: bool,
    #[serde(default)]
    restart: bool,
    targets: Vec<TargetItem>,
}

/// Parses one text frame.
pub(crate) fn parse(text: &str) -> Result<ClientMessage, ParseError> {
    // Only an object: a derived struct would also be read from an array.
    let object = text
        .trim_start_matches([' ', '\t', '\n', '\r'])
        .starts_with('{');
    if let Some(m) = object
        .then(|| serde_json::from_str::<SetpointsText>(text).ok())
        .flatten()
        .filter(|m| m.kind == "setpoints")
    {
        return Ok(ClientMessage::Setpoints(SetpointBatch {
            seq: m.seq,
            ack: m.ack,
            restart: m.restart,
            targets: m.targets,
        }));
    }
    parse_any(text)
}

/// Parses one text frame of any type, the long way.
fn parse_any(text: &str) -> Result<ClientMessage, ParseError> {
    let mut value: Value = serde_json::from_str(text).map_err(|e| ParseError {
        code: ErrorCode::BadJson,
        message: format!("not valid JSON: {e}"),
        seq: None,
    })?;
    let seq = value.get("seq").and_then(Value::as_u64);
    let bad = |message: String| ParseError {
        code: ErrorCode::BadMessage,
        message,
        seq,
    };
    // Checked here, once for every type: a `move` takes its `seq` out of the
    // body before the body is parsed, so a `seq` that is no u64 would
    // otherwise pass as none and the move start unquoted. `null` is no seq.
    if let Some(other) = value.get("seq").filter(|v| !(v.is_u64() || v.is_null())) {
        return Err(bad(format!(
            "`seq` must be an integer 0..=18446744073709551615, not {}",
            json_kind_or_value(other)
        )));
    }
    let obj = value
        .as_object_mut()
        .ok_or_else(|| bad("a message is a JSON object with a `type`".into()))?;
    let kind = match obj.remove("type") {
        Some(Value::String(s)) => s,
        Some(other) => {
            return Err(bad(format!(
                "`type` must be a string ({TYPES}), not {}",
                json_kind(&other)
            )))
        }
        None => return Err(bad(format!("missing `type` ({TYPES})"))),
    };
    let rest = Value::Object(std::mem::take(obj));
    let field_err = |e: serde_json::Error| bad(format!("`{kind}`: {e}"));
    match kind.as_str() {
        "subscribe" => serde_json::from_value(rest).map(ClientMessage::Subscribe),
        "unsubscribe" => serde_json::from_value::<SeqOnly>(rest)
            .map(|s| ClientMessage::Unsubscribe { seq: s.seq }),
        "setpoints" => serde_json::from_value(rest).map(ClientMessage::Setpoints),
        "watchdog" => serde_json::from_value(rest).map(ClientMessage::Watchdog),
        "ping" => {
            serde_json::from_value::<SeqOnly>(rest).map(|s| ClientMessage::Ping { seq: s.seq })
        }
        "move" => {
            let mut rest = rest;
            if let Some(obj) = rest.as_object_mut() {
                obj.remove("seq");
            }
            serde_json::from_value(rest).map(|request| ClientMessage::Move { seq, request })
        }
        "grasp" | "grasp_release" | "grasp_stop" => return parse_grasp(&kind, rest, seq),
        "enable" => serde_json::from_value(rest).map(ClientMessage::Enable),
        "disable" => serde_json::from_value(rest).map(ClientMessage::Disable),
        "estop" => serde_json::from_value(rest).map(ClientMessage::Estop),
        other => return Err(bad(format!("unknown type `{other}` ({TYPES})"))),
    }
    .map_err(field_err)
}

/// The JSON kind of a value, for error messages ("a number", "null", ...).
fn json_kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// A value's kind, or the value itself for a number (`-1`, `2.5`).
fn json_kind_or_value(v: &Value) -> String {
    match v {
        Value::Number(n) => n.to_string(),
        other => json_kind(other).to_owned(),
    }
}

/// Parses a `grasp`, `grasp_release` or `grasp_stop` (the message's
/// object without its `type`).
fn parse_grasp(kind: &str, rest: Value, seq: Option<u64>) -> Result<ClientMessage, ParseError> {
    let mut obj = match rest {
        Value::Object(obj) => obj,
        _ => Map::new(),
    };
    let bad = |message: String| ParseError {
        code: ErrorCode::BadMessage,
        message,
        seq,
    };
    obj.remove("seq");
    let field_err = |e: serde_json::Error| bad(format!("`{kind}`: {e}"));
    match kind {
        "grasp" => {
            let hand = match obj.remove("hand") {
                Some(Value::String(h)) => h,
                Some(_) => return Err(bad("`grasp`: `hand` must be a string".into())),
                None => return Err(bad("`grasp`: missing `hand` (the hand's name)".into())),
            };
            let request: GraspRequest =
                serde_json::from_value(Value::Object(obj)).map_err(field_err)?;
            Ok(ClientMessage::Grasp { seq, hand, request })
        }
        "grasp_release" => {
            let id = grasp_id(kind, &mut obj).map_err(bad)?;
            let request: ReleaseRequest =
                serde_json::from_value(Value::Object(obj)).map_err(field_err)?;
            Ok(ClientMessage::GraspRelease { seq, id, request })
        }
        _ => {
            let id = grasp_id(kind, &mut obj).map_err(bad)?;
            if let Some(other) = obj.keys().next() {
                return Err(bad(format!(
                    "`{kind}`: unknown field `{other}`, expected `seq` or `id`"
                )));
            }
            Ok(ClientMessage::GraspStop { seq, id })
        }
    }
}

fn grasp_id(kind: &str, obj: &mut Map<String, Value>) -> Result<u64, String> {
    match obj.remove("id") {
        Some(v) => v.as_u64().ok_or_else(|| {
            format!("`{kind}`: `id` must be a grasp's id (an integer 1..), not {v}")
        }),
        None => Err(format!(
            "`{kind}`: missing `id` (the grasp's id, as `grasp_started` gave it)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn setpoints_read_straight_agree_with_the_long_way() {
        let texts = [
            r#"{"type":"setpoints","targets":[{"id":1,"position_deg":10.5,"speed_dps":30}]}"#,
            r#"{"targets":[{"id":2,"speed_dps":-5}],"seq":7,"type":"setpoints","ack":true}"#,
            r#"{"type":"setpoints","seq":null,"restart":true,"targets":[{"hand":"left","joint":"index","position_deg":1}]}"#,
            r#"{"type":"setpoints","targets":[]}"#,
            // Refused: the long way's errors.
            r#"{"type":"setpoints","targets":[{"id":1,"position":3}]}"#,
            r#"{"type":"setpoints","seq":-1,"targets":[]}"#,
            r#"{"type":"setpoints","targets":[{"id":1}],"extra":1}"#,
            r#"{"type":"setpoint","targets":[]}"#,
            r#"{"type":"setpoints"}"#,
        ];
        for t in texts {
            assert_eq!(parse(t), parse_any(t), "{t}");
        }
        assert!(parse(texts[0]).is_ok() && parse(texts[4]).is_err());
    }

    #[test]
    fn setpoints_read_straight_take_no_text_the_long_way_refuses() {
        let texts = [
            // Not an object: a struct may be read from an array.
            r#"["setpoints",null,false,false,[{"id":1,"position_deg":10}]]"#,
            r#" ["setpoints",3,true,true,[]]"#,
            // `type` not a string: an enum may be read from `{"variant":null}`.
            r#"{"type":{"setpoints":null},"targets":[{"id":1,"position_deg":10}]}"#,
            // Agreed already; kept so that they stay so.
            r#"{"type":"setpoints","type":"setpoints","targets":[]}"#,
            r#"{"type":"ping","type":"setpoints","targets":[]}"#,
            r#"{"type":"setpoints","seq":1,"seq":2,"targets":[]}"#,
            r#"{"type":"setpoints","seq":-0,"targets":[]}"#,
            r#"{"type":"setpoints","seq":1.0,"targets":[]}"#,
            r#"{"type":"setpoints","seq":18446744073709551615,"targets":[]}"#,
            r#"{"type":"setpoints","seq":18446744073709551616,"targets":[]}"#,
            r#"{"type":"setpoints","targets":[{"id":1,"position_deg":1e400}]}"#,
            r#"{"type":"setpoints","targets":[{"id":1,"position_deg":-0}]}"#,
            r#"{"type":"setpoints","targets":[{"id":99999999999999999999}]}"#,
            r#"{"type":"setpoints","targets":[{"id":1,"id":2}]}"#,
            r#"{"type":"set\u0070oints","t\u0061rgets":[]}"#,
            r#"{"type":"Setpoints","targets":[]}"#,
            r#"{"type":"setpoints","targets":[],"ack":null}"#,
            r#"{"type":"setpoints","targets":[{"id":1,"hand":{"x":[1,{}]}}]}"#,
            r#"{"type":"setpoints","targets":[[null,1,null,null,10.0,null]]}"#,
            r#""setpoints""#,
            r#"null"#,
        ];
        let differ: Vec<_> = texts
            .iter()
            .filter(|t| parse(t) != parse_any(t))
            .map(|t| (t, parse(t)))
            .collect();
        assert!(differ.is_empty(), "{differ:#?}");
    }

    #[test]
    fn parses_each_type_and_names_what_is_wrong() {
        assert!(matches!(
            parse(r#"{"type":"ping","seq":3}"#),
            Ok(ClientMessage::Ping { seq: Some(3) })
        ));
        let m = parse(r#"{"type":"setpoints","seq":1,"targets":[{"id":1,"position_deg":5}]}"#);
        assert!(matches!(m, Ok(ClientMessage::Setpoints(b)) if b.targets.len() == 1 && !b.ack));
        let e = parse(r#"{"type":"setpoints","seq":9,"targets":[{"id":1,"pos":5}]}"#).unwrap_err();
        assert_eq!((e.code, e.seq), (ErrorCode::BadMessage, Some(9)));
        assert!(e.message.contains("pos"), "{}", e.message);
        assert_eq!(parse("{").unwrap_err().code, ErrorCode::BadJson);
        assert!(parse(r#"{"type":"dance"}"#)
            .unwrap_err()
            .message
            .contains("dance"));
        assert!(parse(r#"[1]"#).is_err());
        let e = parse(r#"{"type":5,"seq":2}"#).unwrap_err();
        assert_eq!((e.code, e.seq), (ErrorCode::BadMessage, Some(2)));
        assert!(
            e.message.contains("`type` must be a string"),
            "{}",
            e.message
        );
        assert!(!e.message.contains("missing"), "{}", e.message);
        assert!(parse(r#"{"seq":2}"#)
            .unwrap_err()
            .message
            .contains("missing `type`"));
        for text in [
            r#"{"type":"move","seq":"a","joints":[{"id":1,"position_deg":5}],"duration_ms":100}"#,
            r#"{"type":"ping","seq":-1}"#,
            r#"{"type":"ping","seq":2.5}"#,
            r#"{"type":"setpoints","seq":"1","targets":[]}"#,
        ] {
            let e = parse(text).unwrap_err();
            assert_eq!((e.code, e.seq), (ErrorCode::BadMessage, None), "{text}");
            assert!(
                e.message.contains("`seq` must be an integer"),
                "{}",
                e.message
            );
        }
        let s = parse(r#"{"type":"subscribe","fields":["angle_deg"],"rate_hz":10}"#);
        assert!(
            matches!(s, Ok(ClientMessage::Subscribe(s)) if s.fields == Some(vec![Field::AngleDeg]))
        );
    }
}
