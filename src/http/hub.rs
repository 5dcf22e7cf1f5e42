//! What all WebSocket connections share: the watchdog event channel (every
//! subscriber hears when any teleop stream stops), connection ids, and
//! counters for `/metrics`.

use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::broadcast;

use crate::http::ws::messages::WatchdogEvent;

/// Watchdog events a slow connection may fall behind on before it counts drops.
const EVENT_BACKLOG: usize = 256;

#[derive(Debug)]
pub struct WsHub {
    events: broadcast::Sender<WatchdogEvent>,
    next_client: AtomicU64,
    pub connections: AtomicU64,
    pub dropped_samples: AtomicU64,
    pub dropped_events: AtomicU64,
    pub dropped_replies: AtomicU64,
    /// Telemetry JSON shared by connections with the same subscription.
    pub fragments: crate::http::ws::telemetry::FragmentCache,
}

impl Default for WsHub {
    fn default() -> Self {
        Self {
            events: broadcast::channel(EVENT_BACKLOG).0,
            next_client: AtomicU64::new(1),
            connections: AtomicU64::new(0),
            dropped_samples: AtomicU64::new(0),
            dropped_events: AtomicU64::new(0),
            dropped_replies: AtomicU64::new(0),
            fragments: Default::default(),
        }
    }
}

impl WsHub {
    pub fn next_client_id(&self) -> u64 {
        self.next_client.fetch_add(1, Ordering::Relaxed)
    }

    pub fn subscribe(&self) -> broadcast::Receiver<WatchdogEvent> {
        self.events.subscribe()
    }

    pub fn publish(&self, event: WatchdogEvent) {
        // No listener is fine: the event is also logged by the caller.
        let _ = self.events.send(event);
    }

    pub fn count(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }
}
