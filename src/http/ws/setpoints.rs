//! A `setpoints` batch: validate every target first (bus, device, state,
//! wire range, soft limits, with the REST API's own conversion), then store
//! them all, one store write per bus. One bad target rejects the batch:
//! nothing of it is applied.

use super::messages::{ErrorCode, SetpointBatch, TargetItem};
use crate::bus::{BusError, Source};
use crate::control::batch::BatchItem;
use crate::control::error::{ControlError, InvalidKind};
use crate::control::joints::device_id;
use crate::control::streams::{Applied, Streams};
use crate::control::targets::TargetRequest;
use crate::control::JointRef;
use crate::http::state::AppState;

/// Most targets one batch may carry (16 joints × a few buses, with room).
pub(crate) const MAX_BATCH: usize = 256;

/// A rejected message: code, words, and the field at fault.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct WsError {
    pub code: ErrorCode,
    pub message: String,
    pub field: Option<String>,
}

impl WsError {
    pub(crate) fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
            field: None,
        }
    }

    fn with_field(mut self, field: String) -> Self {
        self.field = Some(field);
        self
    }
}

/// The control core's refusals as WebSocket error codes: each kind once,
/// here, not through HTTP statuses.
impl From<ControlError> for WsError {
    fn from(e: ControlError) -> Self {
        let field = e.field().map(str::to_owned);
        let code = match &e {
            ControlError::Invalid { kind, .. } => match kind {
                InvalidKind::SoftLimit => ErrorCode::OutOfLimit,
                InvalidKind::Duplicate => ErrorCode::BadMessage,
                InvalidKind::Value
                | InvalidKind::OutOfRange
                | InvalidKind::CalibratedRange
                | InvalidKind::WouldOpen => ErrorCode::OutOfRange,
            },
            ControlError::NotFound { kind, .. } if kind == "unknown-bus" => ErrorCode::UnknownBus,
            ControlError::NotFound { .. } => ErrorCode::UnknownDevice,
            ControlError::Conflict { .. } => ErrorCode::WrongState,
            ControlError::Bus(BusError::UnknownDevice { .. }) => ErrorCode::UnknownDevice,
            ControlError::Bus(
                BusError::WrongState(_) | BusError::Refused { .. } | BusError::Preempted,
            ) => ErrorCode::WrongState,
            ControlError::Bus(_)
            | ControlError::StateUnwritable(_)
            | ControlError::Storage { .. }
            | ControlError::Unreadable(_)
            | ControlError::Internal(_) => ErrorCode::BusError,
        };
        WsError {
            code,
            message: e.to_string(),
            field,
        }
    }
}

/// Validates and stores a batch, each joint's targets under the epoch of
/// its stream on this connection (`streams`): the core's one teleop step.
pub(crate) fn apply(
    state: &AppState,
    batch: &SetpointBatch,
    streams: &mut Streams,
) -> Result<Applied, WsError> {
    if batch.targets.is_empty() {
        return Err(WsError::new(ErrorCode::BadMessage, "`targets` is empty"));
    }
    if batch.targets.len() > MAX_BATCH {
        return Err(WsError::new(
            ErrorCode::TooMany,
            format!(
                "{} targets in one batch; at most {MAX_BATCH}",
                batch.targets.len()
            ),
        ));
    }
    let items = named(state, &batch.targets)?;
    Ok(streams.apply(state.control(), &items, batch.restart, Source::Websocket)?)
}

/// Each target with the joint it names.
fn named(state: &AppState, targets: &[TargetItem]) -> Result<Vec<BatchItem>, WsError> {
    let mut items = Vec::with_capacity(targets.len());
    for (i, t) in targets.iter().enumerate() {
        let field = format!("targets[{i}].");
        let (bus, id) = joint_of(state, t, &field)?;
        items.push(BatchItem {
            joint: JointRef { bus, id },
            request: TargetRequest {
                position_deg: t.position_deg,
                speed_dps: t.speed_dps,
            },
            field,
        });
    }
    Ok(items)
}

/// The bus and id a target names: by `id` (on `bus`, or the only
/// bus), or by `hand` and `joint` name.
fn joint_of(state: &AppState, t: &TargetItem, field: &str) -> Result<(String, u8), WsError> {
    match (t.id, &t.hand, &t.joint) {
        (Some(id), None, None) => {
            let name = bus_name(state, t).map_err(|e| e.with_field(format!("{field}bus")))?;
            // The field's name is written out only for a refused id.
            let id = match device_id("", id) {
                Ok(id) => id,
                Err(_) => device_id(&format!("{field}id"), id)?,
            };
            Ok((name, id))
        }
        (None, Some(hand), Some(joint)) if t.bus.is_none() => {
            let found = state
                .control()
                .hand(hand)
                .map_err(|e| WsError::from(e).with_field(format!("{field}hand")))?
                .joint(joint)
                .ok_or_else(|| {
                    WsError::new(
                        ErrorCode::UnknownDevice,
                        format!("hand `{hand}` has no joint `{joint}`"),
                    )
                    .with_field(format!("{field}joint"))
                })?;
            Ok((found.bus.clone(), found.id))
        }
        _ => Err(WsError::new(
            ErrorCode::BadMessage,
            "name the joint by `id` (and `bus`), or by `hand` and `joint`",
        )
        .with_field(field.trim_end_matches('.').to_string())),
    }
}

/// The target's bus, or the only bus when it names none.
fn bus_name(state: &AppState, t: &TargetItem) -> Result<String, WsError> {
    if let Some(name) = &t.bus {
        state.control().reader(name)?;
        return Ok(name.clone());
    }
    let mut names = state.control().readers().map(|b| b.name().to_owned());
    match (names.next(), names.next()) {
        (Some(only), None) => Ok(only),
        _ => Err(WsError::new(
            ErrorCode::BadMessage,
            "`bus` is required when the daemon has more than one bus",
        )),
    }
}
