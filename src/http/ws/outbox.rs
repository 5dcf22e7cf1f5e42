//! A connection's replies on their way to its writer: a bounded queue
//! (a client that sends faster than it reads loses what does not fit,
//! counted), except a stream's end, which is held, in order, until there
//! is room: a client that never hears it streams on into refusals.

use std::collections::VecDeque;

use tokio::sync::mpsc::{self, error::TrySendError};

use super::messages::ServerMessage;
use crate::http::hub::WsHub;
use crate::http::state::AppState;

/// Replies (acks, errors) a connection may have queued; beyond, they are dropped and counted.
pub(super) const OUT_QUEUE: usize = 64;
/// Stream ends a connection may hold while its queue is full; a client
/// that leaves more untaken reads nothing, and is closed.
pub(super) const MAX_HELD: usize = 1024;

pub(super) struct Outbox {
    tx: mpsc::Sender<ServerMessage>,
    held: VecDeque<ServerMessage>,
    state: AppState,
}

impl Outbox {
    pub(super) fn new(tx: mpsc::Sender<ServerMessage>, state: AppState) -> Self {
        Self {
            tx,
            held: VecDeque::new(),
            state,
        }
    }

    /// The queue, for the tasks that answer later (they wait for room).
    pub(super) fn sender(&self) -> &mpsc::Sender<ServerMessage> {
        &self.tx
    }

    /// Whether replies wait for room.
    pub(super) fn holds(&self) -> bool {
        !self.held.is_empty()
    }

    /// More stream ends wait than a reading client would leave.
    pub(super) fn overfull(&self) -> bool {
        self.held.len() > MAX_HELD
    }

    /// The oldest reply waiting for room.
    pub(super) fn pop_held(&mut self) -> Option<ServerMessage> {
        self.held.pop_front()
    }

    /// Queues a reply behind any held ones, so that the client hears them in order.
    pub(super) fn reply(&mut self, msg: ServerMessage) {
        self.send_held();
        if !self.held.is_empty() {
            return self.hold_or_drop(msg);
        }
        match self.tx.try_send(msg) {
            Ok(()) => {}
            Err(TrySendError::Full(msg)) => self.hold_or_drop(msg),
            Err(TrySendError::Closed(_)) => WsHub::count(&self.state.ws().unsent_replies, 1),
        }
    }

    fn hold_or_drop(&mut self, msg: ServerMessage) {
        if matches!(msg, ServerMessage::StreamEnded { .. }) {
            self.held.push_back(msg);
        } else {
            WsHub::count(&self.state.ws().dropped_replies, 1);
        }
    }

    /// Moves held replies into the queue while it has room.
    pub(super) fn send_held(&mut self) {
        while let Some(msg) = self.held.pop_front() {
            match self.tx.try_send(msg) {
                Ok(()) => {}
                Err(TrySendError::Full(msg)) => {
                    self.held.push_front(msg);
                    return;
                }
                Err(TrySendError::Closed(_)) => {
                    let lost = 1 + self.held.len() as u64;
                    WsHub::count(&self.state.ws().unsent_replies, lost);
                    self.held.clear();
                    return;
                }
            }
        }
    }
}
