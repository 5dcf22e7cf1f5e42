//! The sending half of one connection. It alone writes to the socket, so a
//! client that stops reading stalls only this task: telemetry ticks it
//! could not take are skipped and counted (`dropped`), events it fell
//! behind on are counted (`dropped_events`), and its queue stays bounded.
//! A client that takes nothing for [`SLOW_CLIENT`] is closed with 1008
//! "too slow"; on daemon shutdown every connection is closed with 1001.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use axum::extract::ws::{close_code, CloseFrame, Message, Utf8Bytes};
use futures_util::stream::{select_all, SelectAll};
use futures_util::{FutureExt, Sink, SinkExt, Stream, StreamExt};
use tokio::sync::{mpsc, watch};
use tokio::time::interval;
use tokio_stream::wrappers::{errors::BroadcastStreamRecvError, BroadcastStream, WatchStream};

use super::messages::{EventBody, ServerMessage};
use super::telemetry::Subscription;
use super::ticker::Ticker;
use crate::bus::handle::WireAck;
use crate::http::state::AppState;

/// An ack the writer sends once every bus write of a batch is on the wire.
#[derive(Debug, Clone)]
pub(crate) struct PendingAck {
    pub ref_seq: Option<u64>,
    pub joints: usize,
    pub accepted: Instant,
    pub writes: Vec<(String, u64)>,
}

/// Longest wait for a batch to reach the wire before the client hears so.
const ACK_TIMEOUT: Duration = Duration::from_secs(1);
/// Longest a client may leave one message untaken before it is closed
/// (1008 "too slow"): longer than any pause a live client takes, short
/// enough that a dead one does not hold its writer for minutes.
pub(crate) const SLOW_CLIENT: Duration = Duration::from_secs(8);
/// A close frame's reason holds at most 123 bytes (RFC 6455 §5.5).
const MAX_CLOSE_REASON: usize = 123;

/// `reason` cut (on a character boundary) to fit a close frame.
fn fit_close_reason(reason: &str) -> &str {
    let mut end = reason.len().min(MAX_CLOSE_REASON);
    while !reason.is_char_boundary(end) {
        end -= 1;
    }
    &reason[..end]
}

/// How long a close frame may take to go out before the socket is dropped.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(1);
/// How often pending acks are checked for that timeout.
const ACK_SWEEP: Duration = Duration::from_millis(100);

type Events = SelectAll<Pin<Box<dyn Stream<Item = Result<EventBody, u64>> + Send>>>;
type Acks = SelectAll<Pin<Box<dyn Stream<Item = (String, WireAck)> + Send>>>;

pub(crate) struct Writer<S> {
    state: AppState,
    sink: S,
    telemetry_seq: u64,
    event_seq: u64,
    last_sample: Option<Instant>,
    dropped: u64,
    /// This client's skipped samples since it connected, for `/metrics`.
    client_drops: Arc<AtomicU64>,
    dropped_events: u64,
    pending: Vec<PendingAck>,
    on_wire: HashMap<String, WireAck>,
}

impl<S> Writer<S>
where
    S: Sink<Message> + Unpin + Send,
{
    pub(crate) fn new(state: AppState, sink: S) -> Self {
        Self {
            state,
            sink,
            telemetry_seq: 0,
            event_seq: 0,
            last_sample: None,
            dropped: 0,
            client_drops: Arc::default(),
            dropped_events: 0,
            pending: Vec::new(),
            on_wire: HashMap::new(),
        }
    }

    /// Counts this client's skipped samples in `counter` as well.
    pub(crate) fn counting_drops_in(mut self, counter: Arc<AtomicU64>) -> Self {
        self.client_drops = counter;
        self
    }

    /// Runs until the reader drops its side of `out` or the socket fails.
    pub(crate) async fn run(
        mut self,
        mut out: mpsc::Receiver<ServerMessage>,
        sub: watch::Receiver<Option<Arc<Subscription>>>,
        mut acks_in: mpsc::Receiver<PendingAck>,
        mut close_requests: mpsc::Receiver<(u16, String)>,
    ) {
        let mut events = self.event_streams();
        let mut wire = self.ack_streams();
        let mut ticker = Ticker::new(sub.borrow().as_deref());
        let mut sweep = interval(ACK_SWEEP);
        let mut shutdown_rx = self.state.ws().shutdown_signal();
        // Made once, not at every wake-up: each would register a waiter
        // with the channel and drop it again, once per telemetry tick.
        // The guard `wait_for` returns is not `Send`: dropped inside.
        let shutdown = async move { shutdown_rx.wait_for(|&s| s).await.map(drop) }.fuse();
        let mut shutdown = std::pin::pin!(shutdown);
        let mut sub_changes = WatchStream::from_changes(sub.clone());
        loop {
            let subscribed = sub.borrow().is_some();
            let ok = tokio::select! {
                biased;
                Ok(()) = &mut shutdown => {
                    self.close(close_code::AWAY, "daemon shutting down").await;
                    break;
                }
                // Before `out`: the reader asks, then drops its side of `out`.
                Some((code, reason)) = close_requests.recv() => {
                    self.close(code, &reason).await;
                    break;
                }
                msg = out.recv() => match msg {
                    Some(m) => self.reply(&m).await,
                    None => break,
                },
                changed = sub_changes.next() => {
                    if changed.is_none() { break; }
                    ticker = Ticker::new(sub.borrow().as_deref());
                    self.last_sample = None;
                    true
                }
                Some(item) = events.next() => self.event(item).await,
                // The bus may have put the batch on the wire before its
                // pending ack got here: flush now, not on the next write.
                Some(ack) = acks_in.recv() => { self.pending.push(ack); self.flush_acks().await }
                // Only while an ack waits: the bus moves its wire ack at
                // every control frame, and a writer with nothing to ack
                // (every telemetry-only client) need not wake for each.
                Some((bus, ack)) = wire.next(), if !self.pending.is_empty() => { self.on_wire.insert(bus, ack); self.flush_acks().await }
                _ = sweep.tick(), if !self.pending.is_empty() => self.expire_acks().await,
                _ = ticker.tick(), if subscribed => self.telemetry(&sub).await,
            };
            if !ok {
                break;
            }
        }
        self.count_unsent(&mut out);
    }

    /// Replies the client will never see: counted, not silently lost.
    fn count_unsent(&self, out: &mut mpsc::Receiver<ServerMessage>) {
        out.close();
        while out.try_recv().is_ok() {
            crate::http::hub::WsHub::count(&self.state.ws().unsent_replies, 1);
        }
    }

    /// A reply to a request; one the socket refused is counted.
    async fn reply(&mut self, msg: &ServerMessage) -> bool {
        let ok = self.send(msg).await;
        if !ok {
            crate::http::hub::WsHub::count(&self.state.ws().unsent_replies, 1);
        }
        ok
    }

    /// Writes one message; a client that takes nothing for [`SLOW_CLIENT`]
    /// is closed with 1008 and counted.
    async fn put(&mut self, msg: Message) -> bool {
        // `is_ok` here: the sink's error need not be `Send`, so it must not
        // live across the close below.
        let started = std::time::Instant::now();
        let send = self.sink.send(msg);
        let mut send = std::pin::pin!(send);
        // A socket with room takes the message at the first poll: the
        // timer (one timer-wheel entry made and dropped per message, ten
        // thousand a second with a hundred dashboards) is armed only for a
        // send that has to wait.
        let first = send.as_mut().now_or_never().map(|r| r.is_ok());
        let sent = match first {
            Some(ok) => Ok(ok),
            None => tokio::time::timeout(SLOW_CLIENT, send)
                .await
                .map(|r| r.is_ok()),
        };
        match sent {
            Ok(ok) => {
                self.state.ws().observe_send(started.elapsed());
                ok
            }
            Err(_) => {
                crate::http::hub::WsHub::count(&self.state.ws().slow_disconnects, 1);
                let reason = format!("too slow: no message taken for {} s", SLOW_CLIENT.as_secs());
                self.close(close_code::POLICY, &reason).await;
                false
            }
        }
    }

    /// Best effort: a client that reads nothing may not take the close frame either.
    async fn close(&mut self, code: u16, reason: &str) {
        let frame = CloseFrame {
            code,
            reason: Utf8Bytes::from(fit_close_reason(reason)),
        };
        let _ =
            tokio::time::timeout(CLOSE_TIMEOUT, self.sink.send(Message::Close(Some(frame)))).await;
    }

    fn event_streams(&self) -> Events {
        let mut all: Events = select_all(Vec::new());
        for bus in self.state.control().readers() {
            let s =
                BroadcastStream::new(bus.events()).map(|r| r.map(EventBody::Bus).map_err(lagged));
            all.push(Box::pin(s));
        }
        let hub = BroadcastStream::new(self.state.ws().subscribe())
            .map(|r| r.map(EventBody::Watchdog).map_err(lagged));
        all.push(Box::pin(hub));
        all
    }

    fn ack_streams(&self) -> Acks {
        let mut all: Acks = select_all(Vec::new());
        for bus in self.state.control().readers() {
            let name = bus.name().to_owned();
            all.push(Box::pin(
                WatchStream::new(bus.wire_acks()).map(move |a| (name.clone(), a)),
            ));
        }
        all
    }

    async fn send(&mut self, msg: &ServerMessage) -> bool {
        let Ok(text) = serde_json::to_string(msg) else {
            tracing::error!(?msg, "could not serialise a WebSocket message");
            return true;
        };
        self.put(Message::Text(Utf8Bytes::from(text))).await
    }

    async fn event(&mut self, item: Result<EventBody, u64>) -> bool {
        match item {
            Ok(event) => {
                self.event_seq += 1;
                let dropped_events = std::mem::take(&mut self.dropped_events);
                let msg = ServerMessage::Event {
                    seq: self.event_seq,
                    event,
                    dropped_events,
                };
                self.send(&msg).await
            }
            Err(missed) => {
                self.dropped_events += missed;
                crate::http::hub::WsHub::count(&self.state.ws().dropped_events, missed);
                true
            }
        }
    }

    async fn telemetry(&mut self, sub: &watch::Receiver<Option<Arc<Subscription>>>) -> bool {
        let Some(sub) = sub.borrow().clone() else {
            return true;
        };
        let now = Instant::now();
        self.count_skipped_ticks(&sub, now);
        let mut parts: Vec<Arc<str>> = Vec::with_capacity(sub.buses.len());
        for (name, shape) in sub.buses_and_shapes() {
            if let Ok(bus) = self.state.control().reader(name) {
                let names = |id| self.state.control().joint_name(name, id);
                let cals = |id| self.state.control().calibration(name, id);
                let cache = &self.state.ws().fragments;
                let snap = bus.snapshot();
                let part = super::telemetry::fragment(cache, &sub, shape, &snap, names, cals, now);
                if !part.is_empty() {
                    parts.push(part);
                }
            }
        }
        self.telemetry_seq += 1;
        // Written by hand around the shared fragments, in the
        // shape docs/websocket.md gives for `telemetry`: one buffer sized
        // for all of it, the fragments copied in once.
        let joints_len: usize = parts.iter().map(|p| p.len() + 1).sum();
        let mut text = String::with_capacity(joints_len + 96);
        // Writing to a String cannot fail.
        let _ = write!(
            text,
            r#"{{"type":"telemetry","seq":{},"t_ms":{},"dropped":{},"joints":["#,
            self.telemetry_seq,
            unix_ms(),
            std::mem::take(&mut self.dropped),
        );
        for (i, part) in parts.iter().enumerate() {
            if i > 0 {
                text.push(',');
            }
            text.push_str(part);
        }
        text.push_str("]}");
        self.last_sample = Some(now);
        self.put(Message::Text(Utf8Bytes::from(text))).await
    }

    /// Ticks that passed while the socket was not taking messages.
    fn count_skipped_ticks(&mut self, sub: &Subscription, now: Instant) {
        let Some(last) = self.last_sample else { return };
        let periods = now.duration_since(last).as_secs_f64() * sub.rate_hz;
        let skipped = (periods - 1.0).floor().max(0.0) as u64;
        if skipped > 0 {
            self.dropped += skipped;
            self.client_drops.fetch_add(skipped, Ordering::Relaxed);
            crate::http::hub::WsHub::count(&self.state.ws().dropped_samples, skipped);
        }
    }

    async fn flush_acks(&mut self) -> bool {
        let (done, waiting): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| {
                p.writes
                    .iter()
                    .all(|(bus, seq)| self.on_wire.get(bus).is_some_and(|a| a.seq >= *seq))
            });
        self.pending = waiting;
        for p in done {
            let latency = p
                .writes
                .iter()
                .filter_map(|(bus, _)| self.on_wire.get(bus).and_then(|a| a.at))
                .map(|at| at.saturating_duration_since(p.accepted))
                .max()
                .unwrap_or_default();
            let msg = ServerMessage::Ack {
                ref_seq: p.ref_seq,
                joints: p.joints,
                latency_us: latency.as_micros() as u64,
            };
            if !self.send(&msg).await {
                return false;
            }
        }
        true
    }

    async fn expire_acks(&mut self) -> bool {
        let now = Instant::now();
        let (late, waiting): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| now.duration_since(p.accepted) > ACK_TIMEOUT);
        self.pending = waiting;
        for p in late {
            let msg = ServerMessage::Error {
                ref_seq: p.ref_seq,
                code: super::messages::ErrorCode::BusError,
                message: format!(
                    "targets not seen on the wire within {} ms (bus down or busy?)",
                    ACK_TIMEOUT.as_millis()
                ),
                field: None,
            };
            if !self.send(&msg).await {
                return false;
            }
        }
        true
    }
}

fn lagged(e: BroadcastStreamRecvError) -> u64 {
    match e {
        BroadcastStreamRecvError::Lagged(n) => n,
    }
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

#[cfg(test)]
#[path = "writer_tests.rs"]
mod tests;
