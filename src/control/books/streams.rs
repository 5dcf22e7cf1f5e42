//! Who is streaming setpoints to which joints right now: every live teleop
//! stream (a WebSocket client, the ROS 2 bridge, the LeRobot plugin over
//! WebSocket), so a person at the dashboard sees that a program drives a
//! hand before touching it. Each client's `control::streams::Streams`
//! keeps its entry up to date and removes it when it goes away.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Instant, SystemTime};

use serde::Serialize;
use utoipa::ToSchema;

use crate::control::joints::JointRef;

/// How a streaming client reaches the daemon.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Via {
    Websocket,
    Ros2,
}

/// A client that streams setpoints, as the dashboard names it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, ToSchema)]
pub struct Driver {
    pub via: Via,
    /// The WebSocket connection's number (as in `/metrics`' `client`
    /// label); 0 for the ROS 2 bridge.
    pub client: u64,
    /// The name the client gave (`?client=` on the WebSocket URL), if any.
    pub name: Option<String>,
}

/// One client's live streams.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Driving {
    #[serde(flatten)]
    pub driver: Driver,
    /// Unix ms when its streams began (it has had one live since).
    pub since_ms: u64,
    /// How long ago it last sent setpoints, ms (by the daemon's clock): a
    /// client that stopped sending (its watchdog may have fired) still
    /// holds its streams until it closes or they end.
    pub idle_ms: u64,
    pub joints: Vec<JointRef>,
}

#[derive(Debug)]
struct Entry {
    driver: Driver,
    /// Book-wide order of beginnings: the later of two streams to a joint wins.
    began: u64,
    since: SystemTime,
    last: Instant,
    joints: BTreeSet<JointRef>,
}

/// Every client's live streams, keyed by its registration.
#[derive(Debug, Default)]
pub struct StreamBook {
    next: AtomicU64,
    entries: Mutex<BTreeMap<u64, Entry>>,
}

impl StreamBook {
    fn lock(&self) -> MutexGuard<'_, BTreeMap<u64, Entry>> {
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A client's place in the book, empty until it streams; dropping it
    /// takes the client out.
    pub fn register(self: &Arc<Self>, driver: Driver) -> Registration {
        Registration {
            book: Arc::clone(self),
            key: self.next.fetch_add(1, Ordering::Relaxed),
            driver,
        }
    }

    /// Every client streaming now, oldest first.
    pub fn driving(&self) -> Vec<Driving> {
        let entries = self.lock();
        let mut live: Vec<&Entry> = entries.values().filter(|e| !e.joints.is_empty()).collect();
        live.sort_by_key(|e| e.began);
        live.into_iter()
            .map(|e| Driving {
                driver: e.driver.clone(),
                since_ms: unix_ms(e.since),
                idle_ms: u64::try_from(e.last.elapsed().as_millis()).unwrap_or(u64::MAX),
                joints: e.joints.iter().cloned().collect(),
            })
            .collect()
    }

    /// Who streams to `joint` now (the client that began last, when two do).
    pub fn driver_of(&self, joint: &JointRef) -> Option<Driver> {
        self.lock()
            .values()
            .filter(|e| e.joints.contains(joint))
            .max_by_key(|e| e.began)
            .map(|e| e.driver.clone())
    }
}

fn unix_ms(t: SystemTime) -> u64 {
    t.duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// One client's entry in the [`StreamBook`].
#[derive(Debug)]
pub struct Registration {
    book: Arc<StreamBook>,
    key: u64,
    driver: Driver,
}

impl Registration {
    /// The joints this client streams to now (its live streams); `sent`:
    /// because it just sent setpoints (not because some ended).
    pub fn set_live(&self, joints: impl Iterator<Item = JointRef>, sent: bool) {
        let joints: BTreeSet<JointRef> = joints.collect();
        let mut entries = self.book.lock();
        if joints.is_empty() {
            entries.remove(&self.key);
            return;
        }
        let began = &self.book.next;
        let entry = entries.entry(self.key).or_insert_with(|| Entry {
            driver: self.driver.clone(),
            began: began.fetch_add(1, Ordering::Relaxed),
            since: SystemTime::now(),
            last: Instant::now(),
            joints: BTreeSet::new(),
        });
        entry.joints = joints;
        if sent {
            entry.last = Instant::now();
        }
    }

    /// The client sent setpoints just now.
    pub fn sent(&self) {
        if let Some(e) = self.book.lock().get_mut(&self.key) {
            e.last = Instant::now();
        }
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        self.book.lock().remove(&self.key);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(id: u8) -> JointRef {
        JointRef {
            bus: "b".into(),
            id,
        }
    }

    fn driver(client: u64, name: &str) -> Driver {
        Driver {
            via: Via::Websocket,
            client,
            name: Some(name.into()),
        }
    }

    #[test]
    fn a_client_is_listed_while_it_streams_and_gone_when_it_leaves() {
        let book = Arc::new(StreamBook::default());
        let a = book.register(driver(1, "lerobot"));
        assert!(book.driving().is_empty(), "registered, not streaming yet");
        a.set_live([joint(1), joint(2)].into_iter(), true);
        let listed = book.driving();
        assert_eq!(listed.len(), 1);
        assert_eq!(listed[0].joints, vec![joint(1), joint(2)]);
        assert_eq!(book.driver_of(&joint(2)), Some(driver(1, "lerobot")));
        assert_eq!(book.driver_of(&joint(3)), None);
        a.set_live([joint(2)].into_iter(), false);
        assert_eq!(book.driver_of(&joint(1)), None, "its stream to 1 ended");
        drop(a);
        assert!(book.driving().is_empty());
        assert_eq!(book.driver_of(&joint(2)), None);
    }

    #[test]
    fn two_clients_on_one_joint_name_the_later() {
        let book = Arc::new(StreamBook::default());
        let a = book.register(driver(1, "a"));
        a.set_live([joint(1)].into_iter(), true);
        let b = book.register(driver(2, "b"));
        b.set_live([joint(1)].into_iter(), true);
        assert_eq!(book.driver_of(&joint(1)), Some(driver(2, "b")));
        drop(b);
        assert_eq!(book.driver_of(&joint(1)), Some(driver(1, "a")));
        assert_eq!(book.driving().len(), 1);
    }
}
