//! What all WebSocket connections share: the watchdog event channel (every
//! subscriber hears when any teleop stream stops), connection ids,
//! counters, and the telemetry text shared between like subscriptions.
//! The app state holds it, so it knows nothing of the `ws` module's
//! message types beyond the shared watchdog event.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};

use tokio::sync::broadcast;

use crate::bus::BusSnapshot;
use crate::control::teleop::WatchdogEvent;

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
    /// Replies to requests that never reached the client (it went away).
    pub unsent_replies: AtomicU64,
    /// Clients disconnected for not reading (close 1008 "too slow").
    pub slow_disconnects: AtomicU64,
    /// Telemetry samples skipped per connected client. An entry lives as
    /// long as its connection, so the metric's labels stay bounded.
    client_drops: Mutex<BTreeMap<u64, Arc<AtomicU64>>>,
    /// `true` once the daemon is stopping: every writer closes with 1001.
    shutdown: tokio::sync::watch::Sender<bool>,
    /// Telemetry JSON shared by connections with the same subscription.
    pub fragments: FragmentCache,
    /// How long writing one message to a client's socket took.
    send_latency: Mutex<crate::histogram::Histogram>,
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
            unsent_replies: AtomicU64::new(0),
            slow_disconnects: AtomicU64::new(0),
            send_latency: Mutex::default(),
            client_drops: Mutex::default(),
            shutdown: tokio::sync::watch::channel(false).0,
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

    /// Tells every connection the daemon is going away (close 1001).
    pub fn shut_down(&self) {
        self.shutdown.send_replace(true);
    }

    pub(crate) fn shutdown_signal(&self) -> tokio::sync::watch::Receiver<bool> {
        self.shutdown.subscribe()
    }

    /// The skipped-sample counter of a new connection, listed until
    /// [`Self::forget_client`].
    pub(crate) fn track_client(&self, client: u64) -> Arc<AtomicU64> {
        let counter = Arc::new(AtomicU64::new(0));
        self.clients().insert(client, counter.clone());
        counter
    }

    pub(crate) fn forget_client(&self, client: u64) {
        self.clients().remove(&client);
    }

    /// (client id, samples skipped) of every connected client.
    pub(crate) fn client_drops(&self) -> Vec<(u64, u64)> {
        let clients = self.clients();
        clients
            .iter()
            .map(|(id, n)| (*id, n.load(Ordering::Relaxed)))
            .collect()
    }

    // std Mutex: held for one map operation, never across an `.await`.
    fn clients(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<AtomicU64>>> {
        self.client_drops.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A connection starts: counted in `connections`.
    pub fn join(&self) {
        self.connections.fetch_add(1, Ordering::Relaxed);
    }

    /// A connection has ended (its writer too). When it was the last one,
    /// the memory the crowd used goes back to the system (see [`crate::mem`]):
    /// otherwise glibc keeps the peak's pages after every client has left.
    pub fn leave(&self) {
        if self.connections.fetch_sub(1, Ordering::Relaxed) == 1 {
            self.fragments.clear();
            crate::mem::release_free_memory();
        }
    }

    pub fn count(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    /// One message written to a client's socket in `took`.
    pub(crate) fn observe_send(&self, took: std::time::Duration) {
        // std Mutex: one array update, never across an `.await`.
        self.send_latency
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .observe(took);
    }

    /// The socket write latencies so far.
    pub(crate) fn send_latency(&self) -> crate::histogram::Histogram {
        self.send_latency
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
}

/// Serialized joints of one bus snapshot for one subscription shape, shared
/// by every connection with that shape: a hundred dashboards at 100 Hz then
/// cost one serialization per snapshot, not one per message. The shape is
/// the caller's key (bus, devices, fields); a snapshot is known by its
/// address, which changes with every new snapshot. The entry holds a weak
/// reference to its snapshot, so that address is not handed to a later
/// snapshot while the entry could still be taken for it.
#[derive(Debug, Default)]
pub struct FragmentCache {
    // std Mutex: held only while one fragment is looked up or built, never
    // across an `.await`.
    entries: Mutex<HashMap<String, Fragment>>,
}

/// A cached fragment and the snapshot it was built from.
type Fragment = (Weak<BusSnapshot>, Arc<str>);

/// Distinct subscription shapes kept; beyond, the cache starts over (a
/// client cannot grow it without bound).
const MAX_FRAGMENTS: usize = 64;

impl FragmentCache {
    /// Drops every cached fragment (no subscriber is left to share them).
    pub fn clear(&self) {
        let mut entries = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        *entries = HashMap::new();
    }

    /// Fragments cached now.
    pub fn cached(&self) -> usize {
        self.entries.lock().unwrap_or_else(|p| p.into_inner()).len()
    }

    /// The text cached for `shape` and this very `snap`, or `build`'s.
    pub fn get_or_build(
        &self,
        shape: &str,
        snap: &Arc<BusSnapshot>,
        build: impl FnOnce() -> String,
    ) -> Arc<str> {
        let mut entries = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((built_from, text)) = entries.get(shape) {
            if std::ptr::eq(built_from.as_ptr(), Arc::as_ptr(snap)) {
                return text.clone();
            }
        }
        let text: Arc<str> = build().into();
        if entries.len() >= MAX_FRAGMENTS && !entries.contains_key(shape) {
            entries.clear();
        }
        entries.insert(shape.to_owned(), (Arc::downgrade(snap), text.clone()));
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_client_leaving_empties_the_fragment_cache() {
        let hub = WsHub::default();
        let snap = Arc::new(BusSnapshot::new("sim0", "/dev/null", 500_000));
        hub.join();
        hub.join();
        hub.fragments.get_or_build("a", &snap, || "[]".into());
        hub.leave();
        assert_eq!(hub.fragments.cached(), 1, "one client still subscribed");
        hub.leave();
        assert_eq!(hub.connections.load(Ordering::Relaxed), 0);
        assert_eq!(hub.fragments.cached(), 0);
    }

    #[test]
    fn a_new_snapshot_at_a_freed_snapshots_address_is_not_served_its_fragment() {
        let cache = FragmentCache::default();
        let old = Arc::new(BusSnapshot::new("sim0", "/dev/null", 500_000));
        let addr = Arc::as_ptr(&old);
        cache.get_or_build("a", &old, || "old".into());
        drop(old);
        // The allocator hands a freed block of the same size straight back;
        // keep every miss alive so the loop ends on a reuse or gives up.
        let mut misses = Vec::new();
        let reused = loop {
            let snap = Arc::new(BusSnapshot::new("sim0", "/dev/null", 500_000));
            if Arc::as_ptr(&snap) == addr || misses.len() >= 64 {
                break snap;
            }
            misses.push(snap);
        };
        assert_eq!(&*cache.get_or_build("a", &reused, || "new".into()), "new");
    }
}
