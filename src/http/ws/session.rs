//! One WebSocket connection: a reader (this task) that parses and applies
//! client messages and runs the watchdog, and a [`Writer`] task that alone
//! writes to the socket. Generic over `Sink`/`Stream` so tests can drive it
//! without a network.

use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{close_code, Message};
use futures_util::{Sink, Stream, StreamExt};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::actions::{spawn_estop, spawn_switch, Switch};
use super::grasp::GraspTasks;
use super::messages::{self, ClientMessage, ErrorCode, ServerMessage, Subscribe, WatchdogRequest};
use super::outbox::{Outbox, MAX_HELD, OUT_QUEUE};
use super::setpoints::{self, WsError};
use super::subscribe::subscription;
use super::telemetry::Subscription;
use super::welcome::welcome;
use super::writer::{PendingAck, Writer};
use crate::control::audit::Command;
use crate::control::books::streams::{Driver, Via};
use crate::control::streams::Streams;
use crate::control::teleop::{WatchdogEvent, MAX_HOLD, MIN_HOLD};
use crate::control::watchdog::{fire_policy, Watchdog};
use crate::http::scope::{Needs, Scope};
use crate::http::state::AppState;
use crate::http::tokens::Caller;

/// Acks waiting for the wire, per connection.
const MAX_PENDING_ACKS: usize = 256;

/// How often a connection looks whether one of its streams was ended
/// (while it has live streams): an atomic read per joint.
const STREAM_CHECK: Duration = Duration::from_millis(10);
/// Serves one connection of a client that gave no name until it goes away.
pub async fn run<Si, St, E>(state: AppState, sink: Si, stream: St)
where
    Si: Sink<Message> + Unpin + Send + 'static,
    St: Stream<Item = Result<Message, E>> + Unpin,
    E: std::fmt::Display,
{
    run_named(state, None, sink, stream).await;
}

/// [`run_as`] an open caller (every scope), as a daemon without tokens
/// serves every connection.
pub async fn run_named<Si, St, E>(state: AppState, name: Option<String>, sink: Si, stream: St)
where
    Si: Sink<Message> + Unpin + Send + 'static,
    St: Stream<Item = Result<Message, E>> + Unpin,
    E: std::fmt::Display,
{
    run_as(state, Caller::open(), name, sink, stream).await;
}

/// Serves one connection until the client goes away: `caller`, the token
/// it connected with (a message its scope does not reach is refused,
/// `forbidden`); `name`, what the client called itself (`?client=`), shown
/// beside the joints it streams to.
pub async fn run_as<Si, St, E>(
    state: AppState,
    caller: Caller,
    name: Option<String>,
    sink: Si,
    mut stream: St,
) where
    Si: Sink<Message> + Unpin + Send + 'static,
    St: Stream<Item = Result<Message, E>> + Unpin,
    E: std::fmt::Display,
{
    let (mut conn, writer, close_tx) = open(&state, caller, name.clone(), sink);
    let client = conn.client;
    conn.reply(welcome(&state, client, name));
    loop {
        if conn.out.overfull() {
            let why = format!("more than {MAX_HELD} stream ends not taken");
            let _ = close_tx.try_send((close_code::POLICY, why));
            break;
        }
        let deadline = conn.watchdog.deadline();
        tokio::select! {
            msg = stream.next() => match msg {
                Some(Ok(Message::Text(text))) => conn.handle(text.as_str()).await,
                Some(Ok(Message::Binary(_))) => conn.reject(None, WsError::new(ErrorCode::BadMessage, "binary frames are not part of jointd.ws.v1; send JSON text")),
                Some(Ok(Message::Close(_))) | None => break,
                // An oversized message or a broken frame ends the session:
                // the client is told why instead of seeing the socket drop.
                Some(Err(e)) => {
                    let _ = close_tx.try_send((close_code::POLICY, format!("message refused: {e}")));
                    break;
                }
                Some(Ok(_)) => {} // ping/pong: the library answers
            },
            // The writer closed the connection (slow client, shutdown, socket error).
            _ = conn.out.sender().closed() => break,
            // Room for a held reply (owned: the handlers borrow `conn`).
            room = conn.out.sender().clone().reserve_owned(), if conn.out.holds() => match (room, conn.out.pop_held()) {
                (Ok(room), Some(msg)) => {
                    room.send(msg);
                    conn.out.send_held();
                }
                _ => break,
            },
            _ = sleep_until(deadline), if deadline.is_some() => conn.fire_watchdog("timeout").await,
            _ = tokio::time::sleep(STREAM_CHECK), if conn.streams.any_live() => conn.end_revoked_streams(),
        }
    }
    end(&state, client, conn, writer).await;
}

/// The session's state and its writer (the only task that writes to the
/// socket), with the queue the reader asks the writer for a close frame on.
fn open<Si>(
    state: &AppState,
    caller: Caller,
    name: Option<String>,
    sink: Si,
) -> (
    Connection,
    tokio::task::JoinHandle<()>,
    mpsc::Sender<(u16, String)>,
)
where
    Si: Sink<Message> + Unpin + Send + 'static,
{
    let client = state.ws().next_client_id();
    let shown = state.control().stream_book().register(Driver {
        via: Via::Websocket,
        client,
        name,
    });
    state.ws().join();
    let (out_tx, out_rx) = mpsc::channel(OUT_QUEUE);
    let (sub_tx, sub_rx) = watch::channel(None);
    let (ack_tx, ack_rx) = mpsc::channel(MAX_PENDING_ACKS);
    let (close_tx, close_rx) = mpsc::channel(1);
    let drops = state.ws().track_client(client);
    let writer = Writer::new(state.clone(), sink).counting_drops_in(drops);
    let writer = tokio::spawn(writer.run(out_rx, sub_rx, ack_rx, close_rx));
    let conn = Connection {
        state: state.clone(),
        client,
        caller,
        out: Outbox::new(out_tx, state.clone()),
        sub: sub_tx,
        acks: ack_tx,
        watchdog: Watchdog::default(),
        streams: Streams::shown_as(shown),
        grasps: GraspTasks::default(),
    };
    (conn, writer, close_tx)
}

/// The session's end: the watchdog fires if it is armed ("closed"), the
/// writer finishes, the hub forgets the client.
async fn end(
    state: &AppState,
    client: u64,
    mut conn: Connection,
    writer: tokio::task::JoinHandle<()>,
) {
    if conn.watchdog.is_armed() {
        conn.fire_watchdog("closed").await;
    }
    drop(conn);
    let _ = writer.await;
    state.ws().forget_client(client);
    state.ws().leave();
}

async fn sleep_until(deadline: Option<Instant>) {
    if let Some(d) = deadline {
        tokio::time::sleep_until(d).await;
    }
}

struct Connection {
    state: AppState,
    client: u64,
    /// The token it connected with.
    caller: Caller,
    out: Outbox,
    sub: watch::Sender<Option<Arc<Subscription>>>,
    acks: mpsc::Sender<PendingAck>,
    watchdog: Watchdog,
    streams: Streams,
    /// Its grasp followers and the grasp releases and stops it waits on.
    grasps: GraspTasks,
}

impl Connection {
    /// Queues a reply ([`Outbox::reply`]).
    fn reply(&mut self, msg: ServerMessage) {
        self.out.reply(msg);
    }

    fn reject(&mut self, ref_seq: Option<u64>, e: WsError) {
        self.reply(ServerMessage::Error {
            ref_seq,
            code: e.code,
            message: e.message,
            field: e.field,
        });
    }

    async fn handle(&mut self, text: &str) {
        let msg = match messages::parse(text) {
            Ok(m) => m,
            Err(e) => return self.reject(e.seq, WsError::new(e.code, e.message)),
        };
        if !self.admitted(&msg) {
            return;
        }
        match msg {
            ClientMessage::Subscribe(s) => self.subscribe(s),
            ClientMessage::Unsubscribe { seq } => {
                self.sub.send_replace(None);
                self.reply(ServerMessage::Unsubscribed { ref_seq: seq });
            }
            ClientMessage::Setpoints(batch) => self.setpoints(batch),
            ClientMessage::Watchdog(w) => self.arm_watchdog(w),
            ClientMessage::Ping { seq } => self.reply(ServerMessage::Pong { ref_seq: seq }),
            ClientMessage::Move { seq, request } => {
                match crate::control::moves::start(self.state.control(), &request).await {
                    Ok(started) => self.reply(ServerMessage::MoveStarted {
                        ref_seq: seq,
                        started,
                    }),
                    Err(e) => self.reject(seq, e.into()),
                }
            }
            ClientMessage::Grasp { seq, hand, request } => {
                let (state, out) = (self.state.clone(), self.out.sender().clone());
                if let Err(e) = self.grasps.start(&state, &out, seq, &hand, &request).await {
                    self.reject(seq, e);
                }
            }
            ClientMessage::GraspRelease { seq, id, request } => {
                if let Err(e) =
                    self.grasps
                        .end(&self.state, self.out.sender(), seq, id, Some(request))
                {
                    self.reject(seq, e);
                }
            }
            ClientMessage::GraspStop { seq, id } => {
                if let Err(e) = self
                    .grasps
                    .end(&self.state, self.out.sender(), seq, id, None)
                {
                    self.reject(seq, e);
                }
            }
            ClientMessage::Enable(req) => {
                spawn_switch(&self.state, self.out.sender(), Switch::Enable, req)
            }
            ClientMessage::Disable(req) => {
                spawn_switch(&self.state, self.out.sender(), Switch::Disable, req)
            }
            ClientMessage::Estop(req) => spawn_estop(&self.state, self.out.sender(), req),
        }
    }

    /// Whether the caller's token reaches the message (refused with
    /// `forbidden` when not); a command that does is told in the audit.
    fn admitted(&mut self, msg: &ClientMessage) -> bool {
        let needs = msg.needs();
        if !needs.allows(self.caller.scope) {
            let why = format!(
                "`{}` needs a token of scope `{}`; token `{}` is `{}`",
                msg.kind(),
                needs.name(),
                self.caller.name,
                self.caller.scope
            );
            self.reject(msg.seq(), WsError::new(ErrorCode::Forbidden, why));
            return false;
        }
        if needs != Needs::Scope(Scope::Read) {
            let what = format!("websocket {}", msg.kind());
            let cmd = Command {
                by: &self.caller.name,
                kind: &what,
                what: &what,
                outcome: "received",
            };
            self.state.control().tell(&cmd, None);
        }
        true
    }

    fn subscribe(&mut self, s: Subscribe) {
        match subscription(&self.state, &s) {
            Ok(sub) => {
                self.reply(ServerMessage::Subscribed {
                    ref_seq: s.seq,
                    buses: sub.buses.clone(),
                    devices: sub.devices.clone(),
                    fields: sub.fields.clone(),
                    rate_hz: sub.rate_hz,
                });
                self.sub.send_replace(Some(Arc::new(sub)));
            }
            Err(e) => self.reject(s.seq, e),
        }
    }

    /// Says at once which of this connection's streams an e-stop, a
    /// disable, a reset, a fault or a mode change ended.
    fn end_revoked_streams(&mut self) {
        for (j, why) in self.streams.end_revoked(self.state.control()) {
            self.reply(ServerMessage::StreamEnded {
                bus: j.bus,
                id: j.id,
                reason: why.name(),
            });
        }
    }

    fn setpoints(&mut self, batch: messages::SetpointBatch) {
        self.end_revoked_streams();
        match setpoints::apply(&self.state, &batch, &mut self.streams) {
            Ok(applied) => {
                self.arm_default_watchdog();
                self.watchdog.feed(&applied.joints, Instant::now());
                if batch.ack {
                    let ack = PendingAck {
                        ref_seq: batch.seq,
                        joints: applied.joints.len(),
                        accepted: applied.accepted,
                        writes: applied.writes,
                    };
                    if self.acks.try_send(ack).is_err() {
                        self.reject(batch.seq, WsError::new(ErrorCode::TooMany, format!("more than {MAX_PENDING_ACKS} acks pending; targets applied, not acknowledged")));
                    }
                }
            }
            Err(e) => self.reject(batch.seq, e),
        }
    }

    fn arm_watchdog(&mut self, w: WatchdogRequest) {
        let hold = Duration::from_millis(w.hold_timeout_ms);
        if !hold.is_zero() && !(MIN_HOLD..=MAX_HOLD).contains(&hold) {
            let msg = format!(
                "hold_timeout_ms = {} is out of range; allowed 0 (off) or {}..={}",
                w.hold_timeout_ms,
                MIN_HOLD.as_millis(),
                MAX_HOLD.as_millis()
            );
            let mut e = WsError::new(ErrorCode::OutOfRange, msg);
            e.field = Some("hold_timeout_ms".into());
            return self.reject(w.seq, e);
        }
        self.watchdog.arm(hold, w.policy, Instant::now());
        self.reply(ServerMessage::WatchdogSet {
            ref_seq: w.seq,
            hold_timeout_ms: w.hold_timeout_ms,
            policy: w.policy,
        });
    }

    /// The config's `[watchdog]` arms for a streaming client that declared none.
    fn arm_default_watchdog(&mut self) {
        let d = self.state.control().watchdog_default();
        if d.hold_timeout_ms > 0 && !self.watchdog.declared() {
            self.watchdog.arm(
                Duration::from_millis(d.hold_timeout_ms),
                d.policy,
                Instant::now(),
            );
        }
    }

    /// Applies the policy to every joint this client commanded, and tells everyone.
    async fn fire_watchdog(&mut self, why: &'static str) {
        let Some((policy, joints)) = self.watchdog.fire() else {
            return;
        };
        tracing::warn!(
            client = self.client,
            ?policy,
            why,
            joints = joints.len(),
            "teleop watchdog fired"
        );
        fire_policy(self.state.control(), policy, &joints).await;
        self.state.ws().publish(WatchdogEvent {
            event: "watchdog",
            client: self.client,
            policy,
            why,
            joints,
        });
    }
}
