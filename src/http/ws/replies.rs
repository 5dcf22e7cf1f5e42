//! The messages the daemon sends a `jointd.ws.v1` client (docs/websocket.md),
//! and the error codes it refuses a message with.

use serde::{Deserialize, Serialize};

use crate::bus::handle::BusEvent;
use crate::control::books::grasps::GraspView;
use crate::control::estop::EstopResult;
use crate::control::moves::MoveView;
use crate::control::teleop::{WatchdogEvent, WatchdogPolicy};

/// The joint fields a telemetry message can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Field {
    AngleDeg,
    TargetDeg,
    SpeedDps,
    QCurrentA,
    State,
    Fault,
    TempC,
    VbusV,
}

impl Field {
    pub(crate) const ALL: [Field; 8] = [
        Field::AngleDeg,
        Field::TargetDeg,
        Field::SpeedDps,
        Field::QCurrentA,
        Field::State,
        Field::Fault,
        Field::TempC,
        Field::VbusV,
    ];
}

/// Error codes of docs/websocket.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum ErrorCode {
    BadJson,
    BadMessage,
    UnknownBus,
    UnknownDevice,
    OutOfRange,
    OutOfLimit,
    WrongState,
    TooMany,
    BusError,
    /// The connection's token does not reach the message's scope.
    Forbidden,
}

/// A message to the client. (`telemetry` is written by the writer around
/// shared JSON fragments: `{"type":"telemetry","seq","t_ms","dropped","joints"}`.)
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub(crate) enum ServerMessage {
    Welcome {
        protocol: &'static str,
        /// This connection's number (the `client` of `/metrics` and of
        /// the stream book).
        client: u64,
        /// The name it gave (`?client=`).
        name: Option<String>,
        buses: Vec<BusInfo>,
        limits: Limits,
    },
    Event {
        seq: u64,
        event: EventBody,
        #[serde(skip_serializing_if = "is_zero")]
        dropped_events: u64,
    },
    Ack {
        ref_seq: Option<u64>,
        joints: usize,
        latency_us: u64,
    },
    Error {
        ref_seq: Option<u64>,
        code: ErrorCode,
        message: String,
        #[serde(skip_serializing_if = "Option::is_none")]
        field: Option<String>,
    },
    Subscribed {
        ref_seq: Option<u64>,
        buses: Vec<String>,
        devices: Option<Vec<u8>>,
        fields: Vec<Field>,
        rate_hz: f64,
    },
    Unsubscribed {
        ref_seq: Option<u64>,
    },
    WatchdogSet {
        ref_seq: Option<u64>,
        hold_timeout_ms: u64,
        policy: WatchdogPolicy,
    },
    Pong {
        ref_seq: Option<u64>,
    },
    /// This connection's setpoint stream to a joint ended: its motion
    /// epoch moved on (`reason`: `estopped`, `disabled`, `reset`, `fault`,
    /// `mode_changed`, `reenabled`, `zero_moved`). It never resumes by itself.
    StreamEnded {
        bus: String,
        id: u8,
        reason: &'static str,
    },
    /// A `move` was accepted: the move as `GET /api/v1/moves/{id}` shows it.
    /// An `enable` or `disable` done, as REST's answer says it: the
    /// joints addressed (`ids` absent: every joint of the bus).
    Done {
        ref_seq: Option<u64>,
        action: &'static str,
        bus: String,
        ids: Option<Vec<u8>>,
    },
    /// An `estop` done: what each bus did, as `POST /api/v1/estop` answers
    /// (`stopped` false: not every device was confirmed stopped).
    Estopped {
        ref_seq: Option<u64>,
        result: EstopResult,
    },
    MoveStarted {
        ref_seq: Option<u64>,
        #[serde(rename = "move")]
        started: MoveView,
    },
    /// A `grasp` was accepted: the grasp as `GET /api/v1/grasps/{id}` shows it.
    GraspStarted {
        ref_seq: Option<u64>,
        grasp: GraspView,
    },
    /// A `grasp_release` ended the grasp (or its bound passed): as it ended.
    GraspReleased {
        ref_seq: Option<u64>,
        grasp: GraspView,
    },
    /// A `grasp_stop` ended the grasp: as it ended.
    GraspStopped {
        ref_seq: Option<u64>,
        grasp: GraspView,
    },
    /// A grasp this connection started ended, however it ended (released,
    /// stopped, an e-stop, a disable, ...): each finger's final state.
    GraspDone {
        grasp: GraspView,
    },
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct BusInfo {
    pub name: String,
    pub baud: u32,
    pub devices: Vec<u8>,
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct Limits {
    pub max_rate_hz: f64,
    pub max_batch: usize,
}

/// An event as sent: a bus's own, or one of this layer (the teleop watchdog).
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub(crate) enum EventBody {
    Bus(BusEvent),
    Watchdog(WatchdogEvent),
}
