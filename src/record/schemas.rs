//! The JSON schemas of a recording's JSON channels (frames, events,
//! setpoints): every field their messages carry, with its type. Each is
//! closed (`additionalProperties: false`); the events schema also says, per
//! event, exactly which fields it carries, so a reader (or a validator)
//! knows a message's shape from its `event` alone.
//!
//! The events are [`BusEvent`](crate::bus::handle::BusEvent) as serde writes
//! it (the WebSocket's shape); the setpoints are what
//! [`super::recorder`] writes of each store write (its
//! [`Source`](crate::bus::Source) flattened in).

use serde_json::{json, Map, Value};

/// `"type": "integer"` with a description.
fn int(what: &str) -> Value {
    json!({"type": "integer", "minimum": 0, "description": what})
}

fn string(what: &str) -> Value {
    json!({"type": "string", "description": what})
}

fn one_of(values: &[&str], what: &str) -> Value {
    json!({"type": "string", "enum": values, "description": what})
}

/// A frame on the wire.
pub fn frame() -> String {
    json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": "jointd wire frame",
        "type": "object",
        "properties": {
            "dir": one_of(&["tx", "rx"], "tx: written by the host; rx: received from a device"),
            "wire_time_ns": int("Unix time the frame was on the wire, ns (the host's estimate)"),
            "hex": {"type": "string", "pattern": "^[0-9A-F]{2}( [0-9A-F]{2}){19}$",
                    "description": "The 20 bytes, hex, space-separated (jointd frame decode reads it)"},
        },
        "required": ["dir", "wire_time_ns", "hex"],
        "additionalProperties": false,
    })
    .to_string()
}

/// Every event, with the fields it carries besides `event`.
pub const EVENTS: &[(&str, &[&str])] = &[
    ("device_online", &["bus", "id"]),
    ("device_offline", &["bus", "id"]),
    ("fault", &["bus", "id", "err_code", "name"]),
    ("bus_up", &["bus"]),
    ("bus_down", &["bus", "reason"]),
    ("id_changed", &["bus", "old", "new"]),
    ("baud_changed", &["bus", "baud"]),
    ("estop", &["bus"]),
    ("found_enabled", &["bus", "id", "state", "on_start"]),
    ("move_started", &["bus", "move_id", "ids", "duration_ms"]),
    ("move_progress", &["bus", "move_id", "progress"]),
    ("move_done", &["bus", "move_id"]),
    ("move_stopped", &["bus", "move_id"]),
    ("move_aborted", &["bus", "move_id", "reason"]),
    (
        "config_written",
        &["bus", "id", "index", "name", "value", "verified_by"],
    ),
    (
        "usb_pipeline",
        &["bus", "mode", "previous", "guard_us", "reason"],
    ),
    (
        "device_reset",
        &["bus", "id", "seen", "state_before", "state"],
    ),
    ("grasp_contact", &["bus", "grasp_id", "id", "contact_deg"]),
    ("grasp_lost", &["bus", "grasp_id", "id", "q_current_a"]),
    ("command", &["bus", "by", "command", "outcome", "repeats"]),
];

/// Every field an event may carry, typed.
fn event_fields() -> Map<String, Value> {
    let names: Vec<&str> = EVENTS.iter().map(|(n, _)| *n).collect();
    let pipeline = ["pipelined", "guarded", "lockstep"];
    let fields = json!({
        "event": one_of(&names, "What happened (docs/websocket.md tells each)"),
        "bus": string("The bus it happened on"),
        "id": {"type": "integer", "minimum": 0, "maximum": 255, "description": "The device's id on the bus"},
        "err_code": int("fault: the device's error code (ERR_CODE)"),
        "name": string("fault: the error's name; config_written: the parameter's (MAX_CUR, ...)"),
        "reason": string("bus_down, move_aborted, usb_pipeline: why"),
        "old": int("id_changed: the id before"),
        "new": int("id_changed: the id now"),
        "baud": int("baud_changed: the line's baud rate now"),
        "state": string("found_enabled, device_reset: the device's state name (run, align, ready, ...)"),
        "on_start": one_of(&["keep", "disable"], "found_enabled: what the config's on_start does with it"),
        "move_id": int("move_*: the move"),
        "ids": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255},
                "description": "move_started: its joints on this bus"},
        "duration_ms": {"type": "number", "description": "move_started: the path's duration, ms"},
        "progress": {"type": "number", "minimum": 0, "maximum": 1,
                     "description": "move_progress: the share of its time gone"},
        "index": int("config_written: the parameter's index"),
        "value": int("config_written: the raw value written"),
        "verified_by": one_of(&["res", "read_back"], "config_written: how the write was confirmed"),
        "mode": one_of(&pipeline, "usb_pipeline: the adapter pipeline's mode now"),
        "previous": one_of(&pipeline, "usb_pipeline: its mode before"),
        "guard_us": int("usb_pipeline: how late a write may reach the adapter now, µs"),
        "seen": one_of(&["announcement", "state_dropped"], "device_reset: what told the daemon"),
        "state_before": string("device_reset: the state before (unknown if never read)"),
        "grasp_id": int("grasp_*: the grasp job"),
        "id": {"type": "integer", "minimum": 0, "maximum": 255, "description": "grasp_*: the joint"},
        "contact_deg": {"type": "number", "description": "grasp_contact: where contact began, degrees (calibrated)"},
        "q_current_a": {"type": "number", "description": "grasp_lost: the q current when the loss was seen, A"},
        "by": string("command: the name of the token it came with"),
        "command": string("command: what, as the front-end names it (`PUT /api/v1/...`, `websocket setpoints`)"),
        "outcome": string("command: the HTTP status, or how the WebSocket answered"),
        "repeats": int("command: more like it in the second before"),
    });
    match fields {
        Value::Object(m) => m,
        _ => Map::new(),
    }
}

/// A device or bus event.
pub fn event() -> String {
    let per_event: Vec<Value> = EVENTS
        .iter()
        .map(|(name, fields)| {
            let mut required = vec!["event"];
            required.extend_from_slice(fields);
            json!({
                "if": {"properties": {"event": {"const": name}}},
                "then": {"required": required, "maxProperties": required.len()},
            })
        })
        .collect();
    json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": "jointd bus event",
        "type": "object",
        "properties": event_fields(),
        "required": ["event", "bus"],
        "additionalProperties": false,
        "allOf": per_event,
    })
    .to_string()
}

/// The sources of targets, as [`crate::bus::Source`] names them.
pub const SOURCES: &[&str] = &[
    "rest",
    "websocket",
    "ros2",
    "move",
    "homing",
    "grasp",
    "hold",
    "aligned",
    "bench",
];

/// One write of targets to a bus's setpoint store.
pub fn setpoint() -> String {
    json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": "jointd targets",
        "type": "object",
        "properties": {
            "source": one_of(SOURCES, "Who wrote them: a client over REST, a WebSocket or ROS 2 stream, \
                a move (sampled each control cycle; a pose go is a move), a homing step, a grasp's finger, the watchdog's \
                hold, a joint's target again after it aligned, the bench"),
            "move_id": int("source move: the move"),
            "seq": int("The write's sequence number in the bus's setpoint store"),
            "targets": {"type": "array", "items": {
                "type": "object",
                "properties": {
                    "id": {"type": "integer", "minimum": 0, "maximum": 255},
                    "position_deg": {"type": "number", "description": "In the joint's calibrated frame"},
                    "speed_dps": {"type": "number", "description": "Output-shaft °/s: the speed limit, or the speed (signed) in speed mode"},
                    "pos_ref_raw": {"type": "integer", "description": "As the wire carries it (Q7 degrees, device frame)"},
                    "spd_ref_raw": {"type": "integer", "description": "The speed limit (or speed, in speed mode), raw"},
                },
                "required": ["id", "position_deg", "pos_ref_raw", "spd_ref_raw"],
                "additionalProperties": false,
            }},
        },
        "required": ["source", "seq", "targets"],
        "additionalProperties": false,
        "if": {"properties": {"source": {"const": "move"}}},
        "then": {"required": ["move_id"]},
        "else": {"not": {"required": ["move_id"]}},
    })
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::handle::BusEvent;
    use crate::bus::handle::ResetSignal;
    use crate::bus::Source;

    /// One of every event (add a new one here: the test then checks it).
    fn every_event() -> Vec<BusEvent> {
        let bus = || "sim0".to_owned();
        vec![
            BusEvent::DeviceOnline {
                bus: bus(),
                dev_id: 1,
            },
            BusEvent::DeviceOffline {
                bus: bus(),
                dev_id: 1,
            },
            BusEvent::Fault {
                bus: bus(),
                dev_id: 1,
                err_code: 3,
                name: "OVER_CUR",
            },
            BusEvent::BusUp { bus: bus() },
            BusEvent::BusDown {
                bus: bus(),
                reason: "gone".into(),
            },
            BusEvent::IdChanged {
                bus: bus(),
                old: 1,
                new: 2,
            },
            BusEvent::BaudChanged {
                bus: bus(),
                baud: 500_000,
            },
            BusEvent::Estop { bus: bus() },
            BusEvent::FoundEnabled {
                bus: bus(),
                dev_id: 1,
                state: "run",
                on_start: "keep",
            },
            BusEvent::MoveStarted {
                bus: bus(),
                move_id: 1,
                ids: vec![1, 2],
                duration_ms: 500.0,
            },
            BusEvent::MoveProgress {
                bus: bus(),
                move_id: 1,
                progress: 0.5,
            },
            BusEvent::MoveDone {
                bus: bus(),
                move_id: 1,
            },
            BusEvent::MoveStopped {
                bus: bus(),
                move_id: 1,
            },
            BusEvent::MoveAborted {
                bus: bus(),
                move_id: 1,
                reason: "estop".into(),
            },
            BusEvent::ConfigWritten {
                bus: bus(),
                dev_id: 1,
                index: 4,
                name: "MAX_CUR",
                value: 100,
                verified_by: "res",
            },
            BusEvent::UsbPipeline {
                bus: bus(),
                mode: "guarded",
                previous: "pipelined",
                guard_us: 200,
                reason: "collision".into(),
            },
            BusEvent::DeviceReset {
                bus: bus(),
                dev_id: 1,
                seen: ResetSignal::Announcement,
                state_before: "run",
                state: "ready",
            },
            BusEvent::GraspContact {
                bus: bus(),
                grasp_id: 1,
                id: 2,
                contact_deg: 31.5,
            },
            BusEvent::GraspLost {
                bus: bus(),
                grasp_id: 1,
                id: 2,
                q_current_a: 0.05,
            },
            BusEvent::Command {
                bus: bus(),
                by: "policy".into(),
                command: "PUT /api/v1/buses/sim0/devices/1/target".into(),
                outcome: "200".into(),
                repeats: 3,
            },
        ]
    }

    /// Whether `v` is of the schema `field`'s JSON type.
    fn typed(field: &Value, v: &Value) -> bool {
        match field["type"].as_str() {
            Some("integer") => v.is_u64() || v.is_i64(),
            Some("number") => v.is_number(),
            Some("string") => v.is_string(),
            Some("array") => v.is_array(),
            _ => false,
        }
    }

    #[test]
    fn every_event_carries_exactly_the_fields_its_schema_lists_with_their_types() {
        let schema: Value = serde_json::from_str(&event()).unwrap();
        let props = schema["properties"].as_object().unwrap();
        let events = every_event();
        assert_eq!(events.len(), EVENTS.len(), "one of each event");
        for e in events {
            let msg = serde_json::to_value(&e).unwrap();
            let msg = msg.as_object().unwrap();
            let name = msg["event"].as_str().unwrap();
            let (_, fields) = EVENTS
                .iter()
                .find(|(n, _)| *n == name)
                .unwrap_or_else(|| panic!("{name} is not in the schema"));
            let mut keys: Vec<&str> = msg.keys().map(String::as_str).collect();
            let mut listed: Vec<&str> = fields.to_vec();
            listed.push("event");
            keys.sort_unstable();
            listed.sort_unstable();
            assert_eq!(keys, listed, "{name}");
            for (k, v) in msg {
                assert!(typed(&props[k], v), "{name}.{k} = {v} against {}", props[k]);
            }
        }
    }

    #[test]
    fn every_source_is_listed_and_only_a_move_has_an_id() {
        let all = [
            Source::Rest,
            Source::Websocket,
            Source::Ros2,
            Source::Move { move_id: 7 },
            Source::Homing,
            Source::Grasp,
            Source::Hold,
            Source::Aligned,
            Source::Bench,
        ];
        assert_eq!(all.len(), SOURCES.len());
        for s in all {
            let v = serde_json::to_value(s).unwrap();
            let name = v["source"].as_str().unwrap();
            assert!(SOURCES.contains(&name), "{name}");
            let keys = v.as_object().unwrap().len();
            assert_eq!(keys, if name == "move" { 2 } else { 1 }, "{v}");
        }
        for text in [frame(), event(), setpoint()] {
            let v: Value = serde_json::from_str(&text).unwrap();
            assert_eq!(v["additionalProperties"], false, "{text}");
        }
    }
}
