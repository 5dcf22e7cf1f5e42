//! `enable`, `disable` and `estop` over the WebSocket: the core's calls
//! REST and ROS 2 make, each in a task of its own so that the connection's
//! reader never waits on a bus (setpoints and a later `estop` go on being
//! read), answered with `done`, `estopped` or `error` quoting the
//! request's `seq`.

use tokio::sync::mpsc;

use super::messages::{EstopRequest, JointsOfBus, ServerMessage};
use super::setpoints::WsError;
use crate::control::ControlResult;
use crate::http::state::AppState;

/// Which way a `JointsOfBus` message switches its joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Switch {
    Enable,
    Disable,
}

impl Switch {
    fn name(self) -> &'static str {
        match self {
            Self::Enable => "enable",
            Self::Disable => "disable",
        }
    }
}

/// Enables or disables the joints `req` names, through the core.
pub(crate) fn spawn_switch(
    state: &AppState,
    out: &mpsc::Sender<ServerMessage>,
    switch: Switch,
    req: JointsOfBus,
) {
    let (control, out) = (state.control().clone(), out.clone());
    tokio::spawn(async move {
        let done: ControlResult<Option<Vec<u8>>> = async {
            let ids = control.group_ids(&req.bus, req.ids)?;
            match switch {
                Switch::Enable => control.enable(&req.bus, ids.clone()).await?,
                Switch::Disable => control.disable(&req.bus, ids.clone()).await?,
            }
            Ok(ids)
        }
        .await;
        let msg = match done {
            Ok(ids) => ServerMessage::Done {
                ref_seq: req.seq,
                action: switch.name(),
                bus: req.bus,
                ids,
            },
            Err(e) => refusal(req.seq, e.into()),
        };
        // The connection may be gone: nobody is left to tell.
        let _ = out.send(msg).await;
    });
}

/// The e-stop of the bus `req` names, or of every bus, through the core.
pub(crate) fn spawn_estop(state: &AppState, out: &mpsc::Sender<ServerMessage>, req: EstopRequest) {
    let (control, out) = (state.control().clone(), out.clone());
    tokio::spawn(async move {
        let result = match &req.bus {
            Some(bus) => control.estop_buses(&[bus.as_str()]).await,
            None => Ok(control.estop_all().await),
        };
        let msg = match result {
            Ok(result) => ServerMessage::Estopped {
                ref_seq: req.seq,
                result,
            },
            Err(e) => refusal(req.seq, e.into()),
        };
        let _ = out.send(msg).await;
    });
}

fn refusal(ref_seq: Option<u64>, e: WsError) -> ServerMessage {
    ServerMessage::Error {
        ref_seq,
        code: e.code,
        message: e.message,
        field: e.field,
    }
}
