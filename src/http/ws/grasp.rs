//! Grasps over `jointd.ws.v1`: `grasp` starts one (the REST body plus
//! `hand`), `grasp_release` and `grasp_stop` end one by id. A thin adapter
//! over [`crate::control::grasp`], the same routine as REST.
//!
//! Ending a grasp waits for its fingers (up to the travel and a bound), so
//! `grasp_release` and `grasp_stop` are answered from a task of their own:
//! the connection keeps reading (setpoints, pings, an e-stop's events)
//! meanwhile. The connection that started a grasp is told when it ended,
//! however it ended (`grasp_done`: released, stopped, or aborted by an
//! e-stop, a disable, a reset, a mode change). These tasks hold only a
//! weak handle on the connection's reply queue, so a connection that
//! closes is not kept open by them, and they end with it.

use tokio::sync::mpsc;
use tokio::task::JoinSet;

use super::messages::{ErrorCode, ServerMessage};
use super::setpoints::WsError;
use crate::control::grasp::{self, GraspRequest, ReleaseRequest};
use crate::http::hub::WsHub;
use crate::http::state::AppState;

/// Grasp tasks (followers, releases, stops) one connection may have running.
pub(crate) const MAX_TASKS: usize = 64;

/// One connection's grasp tasks: aborted when the connection ends.
#[derive(Default)]
pub(crate) struct GraspTasks {
    tasks: JoinSet<()>,
}

impl GraspTasks {
    /// Starts a grasp and answers `grasp_started` with its view; then a
    /// task tells this connection when it ended (`grasp_done`, always
    /// after `grasp_started`).
    pub(crate) async fn start(
        &mut self,
        state: &AppState,
        out: &mpsc::Sender<ServerMessage>,
        seq: Option<u64>,
        hand: &str,
        request: &GraspRequest,
    ) -> Result<(), WsError> {
        self.room()?;
        let started = grasp::start(state.control(), hand, request).await?;
        let id = started.id;
        let out = out.downgrade();
        send(
            state,
            &out,
            ServerMessage::GraspStarted {
                ref_seq: seq,
                grasp: started,
            },
        );
        let Some(job) = state.control().grasps().job(id) else {
            return Ok(());
        };
        let mut done = job.done.subscribe();
        drop(job);
        let state = state.clone();
        self.tasks.spawn(async move {
            if done.wait_for(|d| *d).await.is_err() {
                return;
            }
            if let Ok(grasp) = grasp::get(state.control(), id) {
                send(&state, &out, ServerMessage::GraspDone { grasp });
            }
        });
        Ok(())
    }

    /// Releases (`Some`) or stops (`None`) grasp `id`, answering from a
    /// task once its fingers ended (or with the error that refused it).
    pub(crate) fn end(
        &mut self,
        state: &AppState,
        out: &mpsc::Sender<ServerMessage>,
        seq: Option<u64>,
        id: u64,
        release: Option<ReleaseRequest>,
    ) -> Result<(), WsError> {
        self.room()?;
        let (state, out) = (state.clone(), out.downgrade());
        self.tasks.spawn(async move {
            let answer = match release {
                Some(req) => grasp::release(state.control(), id, &req)
                    .await
                    .map(|grasp| ServerMessage::GraspReleased {
                        ref_seq: seq,
                        grasp,
                    }),
                None => grasp::stop(state.control(), id).await.map(|grasp| {
                    ServerMessage::GraspStopped {
                        ref_seq: seq,
                        grasp,
                    }
                }),
            };
            let msg = answer.unwrap_or_else(|e| {
                let e = WsError::from(e);
                ServerMessage::Error {
                    ref_seq: seq,
                    code: e.code,
                    message: e.message,
                    field: e.field,
                }
            });
            send(&state, &out, msg);
        });
        Ok(())
    }

    /// Refuses a new task beyond [`MAX_TASKS`] (finished ones reaped first).
    fn room(&mut self) -> Result<(), WsError> {
        while self.tasks.try_join_next().is_some() {}
        if self.tasks.len() >= MAX_TASKS {
            return Err(WsError::new(
                ErrorCode::TooMany,
                format!(
                    "more than {MAX_TASKS} grasps followed or being ended on this connection; \
                     wait for some to end"
                ),
            ));
        }
        Ok(())
    }
}

/// Queues a reply for a connection that may have gone (then it is counted
/// as unsent), or whose queue is full (counted as dropped).
fn send(state: &AppState, out: &mpsc::WeakSender<ServerMessage>, msg: ServerMessage) {
    let Some(out) = out.upgrade() else {
        return WsHub::count(&state.ws().unsent_replies, 1);
    };
    match out.try_send(msg) {
        Ok(()) => {}
        Err(mpsc::error::TrySendError::Full(_)) => WsHub::count(&state.ws().dropped_replies, 1),
        Err(mpsc::error::TrySendError::Closed(_)) => WsHub::count(&state.ws().unsent_replies, 1),
    }
}

#[cfg(test)]
mod tests {
    use super::super::messages::{parse as parse_text, ClientMessage};
    use super::*;

    #[test]
    fn parses_the_grasp_messages_and_names_what_is_wrong() {
        let m = parse_text(
            r#"{"type":"grasp","seq":4,"hand":"right","speed_dps":30,"hold_current_a":0.2,
                "joints":[{"joint":"index","close_to_deg":60}]}"#,
        );
        assert!(
            matches!(&m, Ok(ClientMessage::Grasp { seq: Some(4), hand, request })
                if hand == "right" && request.speed_dps == 30.0
                    && request.joints.as_ref().is_some_and(|j| j.len() == 1)),
            "{m:?}"
        );
        let m = parse_text(r#"{"type":"grasp_release","seq":5,"id":3,"open_deg":20}"#);
        assert!(
            matches!(&m, Ok(ClientMessage::GraspRelease { seq: Some(5), id: 3, request })
                if request.open_deg == Some(20.0)),
            "{m:?}"
        );
        assert!(matches!(
            parse_text(r#"{"type":"grasp_release","id":3}"#),
            Ok(ClientMessage::GraspRelease {
                seq: None,
                id: 3,
                ..
            })
        ));
        assert!(matches!(
            parse_text(r#"{"type":"grasp_stop","seq":6,"id":3}"#),
            Ok(ClientMessage::GraspStop {
                seq: Some(6),
                id: 3
            })
        ));
        for (text, says) in [
            (
                r#"{"type":"grasp","seq":1,"speed_dps":30,"hold_current_a":0.2}"#,
                "missing `hand`",
            ),
            (
                r#"{"type":"grasp","seq":1,"hand":2,"speed_dps":30,"hold_current_a":0.2}"#,
                "`hand` must be a string",
            ),
            (
                r#"{"type":"grasp","seq":1,"hand":"h","speed_dps":30,"hold_a":0.2}"#,
                "hold_a",
            ),
            (r#"{"type":"grasp_release","seq":1}"#, "missing `id`"),
            (r#"{"type":"grasp_stop","seq":1,"id":-2}"#, "`id` must be"),
            (
                r#"{"type":"grasp_stop","seq":1,"id":2,"open_deg":3}"#,
                "open_deg",
            ),
            (
                r#"{"type":"grasp_release","seq":1,"id":2,"open":3}"#,
                "open",
            ),
        ] {
            let e = parse_text(text).unwrap_err();
            assert_eq!((e.code, e.seq), (ErrorCode::BadMessage, Some(1)), "{text}");
            assert!(e.message.contains(says), "{text}: {}", e.message);
        }
    }
}
