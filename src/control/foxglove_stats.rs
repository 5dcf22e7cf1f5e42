//! The live Foxglove view's counters ([`crate::foxglove`] counts, `/metrics`
//! reads them): here, below both, so neither imports the other.

use std::sync::atomic::{AtomicU64, Ordering};

/// What the live view did.
#[derive(Debug, Default)]
pub struct FoxgloveStats {
    /// Foxglove clients connected now.
    pub clients: AtomicU64,
    /// Messages handed to the SDK while a client was subscribed to their
    /// channel (a message no client wants is not even encoded).
    pub messages: AtomicU64,
    /// Frames, setpoint writes and events the live view fell too far
    /// behind to see (the buses' taps hold seconds of them).
    pub lost: AtomicU64,
}

impl FoxgloveStats {
    pub fn client_connected(&self) {
        self.clients.fetch_add(1, Ordering::Relaxed);
    }

    /// A client gone; never below zero (at shutdown the SDK can tell the
    /// end of a client it never counted as connected).
    pub fn client_disconnected(&self) {
        let _ = self
            .clients
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| {
                Some(n.saturating_sub(1))
            });
    }
}
