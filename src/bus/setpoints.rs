//! The latest-value store of joint targets: writers overwrite, the bus
//! owner takes what changed since it last looked. A client faster than the
//! wire overwrites; nothing queues.
//!
//! Each target carries the motion epoch it was admitted under, and the
//! store holds the bus's [`MotionAuthority`]: the owner takes only targets
//! whose epoch is still their joint's (see [`super::authority`]).
//!
//! Every target of the bus goes through [`SetpointStore::set_admitted`]
//! (a client's, a stream's, a move's samples, a homing step, a hold), so
//! that is where recordings hear them: each write, with its
//! [`Source`], goes to the store's tap while someone listens.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::{Instant, SystemTime};

use serde::Serialize;
use tokio::sync::broadcast;

use super::authority::{Epoch, MotionAuthority, Revoked};

/// A joint target as the wire carries it (raw Q7 degrees, raw Q15 speed).
/// Units and soft limits are checked before a setpoint gets here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Setpoint {
    pub pos_ref: i16,
    pub spd_ref: i16,
}

/// Who wrote a set of targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "source", rename_all = "snake_case")]
pub enum Source {
    /// A client over REST (`POST .../control/setpoints`), or a direct
    /// caller of [`super::BusHandle::set_targets`].
    Rest,
    /// A client's stream over WebSocket.
    Websocket,
    /// A `JointState` command stream from ROS 2.
    Ros2,
    /// A move's path (a pose go is a move), sampled at each control cycle,
    /// or the hold of a joint that stalled on it.
    Move { move_id: u64 },
    /// A homing job's step (its search speed, its stop, its back-off).
    Homing,
    /// A grasp's finger: closing, holding where an object was lost,
    /// opening on release, holding where it was stopped.
    Grasp,
    /// The watchdog holding joints whose stream stopped.
    Hold,
    /// A joint's latest target again, once it finished aligning.
    Aligned,
    /// The bench's load generator.
    Bench,
}

/// One write of targets as the store took it, for recordings.
#[derive(Debug, Clone, PartialEq)]
pub struct Commanded {
    pub at: SystemTime,
    /// Its sequence number in the store.
    pub seq: u64,
    pub source: Source,
    pub targets: Vec<(u8, Setpoint)>,
}

/// How many writes a recording may fall behind before it loses some
/// (counted): ~4 s of a 1 kHz client, or of a move sampled every frame.
const TAP_LEN: usize = 4096;

/// One slot of the latest-value store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoredSetpoint {
    pub setpoint: Setpoint,
    /// Store-wide sequence number of the write that produced this value.
    pub seq: u64,
    /// When the write was accepted (for setpoint-to-wire latency).
    pub accepted: Instant,
    /// The motion epoch it was admitted under.
    pub epoch: Epoch,
}

/// Latest target per joint. Writers overwrite; the scheduler takes what
/// changed since it last looked (`seq` above what it sent).
#[derive(Debug)]
pub struct SetpointStore {
    slots: Mutex<BTreeMap<u8, StoredSetpoint>>,
    next_seq: AtomicU64,
    authority: MotionAuthority,
    /// Every write, for recordings (sent only while one listens: nothing
    /// is copied otherwise).
    tap: broadcast::Sender<Commanded>,
}

impl Default for SetpointStore {
    fn default() -> Self {
        Self {
            slots: Mutex::default(),
            next_seq: AtomicU64::default(),
            authority: MotionAuthority::default(),
            tap: broadcast::channel(TAP_LEN).0,
        }
    }
}

impl SetpointStore {
    fn lock(&self) -> MutexGuard<'_, BTreeMap<u8, StoredSetpoint>> {
        self.slots.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Stores targets for several joints at once, each admitted now (under
    /// its joint's current epoch); returns the sequence number they share.
    pub fn set(&self, targets: &[(u8, Setpoint)], source: Source) -> u64 {
        let stamped: Vec<(u8, Setpoint, Epoch)> = targets
            .iter()
            .map(|&(id, sp)| (id, sp, self.authority.grant(id).epoch))
            .collect();
        self.set_admitted(&stamped, source)
    }

    /// Stores targets each admitted under the epoch it carries (a move's,
    /// a homing job's, a stream's); returns the sequence number they share.
    /// A recording listening hears the write, in sequence order (taken
    /// under the slots' lock, as the slots are written).
    pub fn set_admitted(&self, targets: &[(u8, Setpoint, Epoch)], source: Source) -> u64 {
        let accepted = Instant::now();
        let mut slots = self.lock();
        let seq = self.next_seq.fetch_add(1, Ordering::Relaxed) + 1;
        if self.tap.receiver_count() > 0 {
            let _ = self.tap.send(Commanded {
                at: SystemTime::now(),
                seq,
                source,
                targets: targets.iter().map(|&(id, sp, _)| (id, sp)).collect(),
            });
        }
        for &(id, setpoint, epoch) in targets {
            slots.insert(
                id,
                StoredSetpoint {
                    setpoint,
                    seq,
                    accepted,
                    epoch,
                },
            );
        }
        seq
    }

    /// Every write from now on, with its source.
    pub fn subscribe(&self) -> broadcast::Receiver<Commanded> {
        self.tap.subscribe()
    }

    /// Who may move which joint.
    pub fn authority(&self) -> &MotionAuthority {
        &self.authority
    }

    /// True when `sp` may still go to joint `id`.
    pub fn admits(&self, id: u8, sp: &StoredSetpoint) -> bool {
        self.authority.admits(id, sp.epoch)
    }

    /// Advances the epochs of `ids` (every id: `None`) and forgets their
    /// targets: nothing admitted before may reach them.
    pub fn revoke(&self, ids: Option<&[u8]>, why: Revoked) {
        match ids {
            None => self.authority.revoke_all(why),
            Some(ids) => ids.iter().for_each(|id| {
                self.authority.revoke(*id, why);
            }),
        }
        self.clear(ids);
    }

    /// The sequence number of the latest write (it may still be landing).
    pub fn latest_seq(&self) -> u64 {
        self.next_seq.load(Ordering::Acquire)
    }

    /// Every stored target with a sequence number above `after`.
    pub fn changed_since(&self, after: u64) -> Vec<(u8, StoredSetpoint)> {
        self.lock()
            .iter()
            .filter(|(_, s)| s.seq > after)
            .map(|(id, s)| (*id, *s))
            .collect()
    }

    pub fn get(&self, id: u8) -> Option<StoredSetpoint> {
        self.lock().get(&id).copied()
    }

    /// Forgets targets (e-stop, disable): a later enable must not jump to a stale target.
    pub fn clear(&self, ids: Option<&[u8]>) {
        let mut slots = self.lock();
        match ids {
            None => slots.clear(),
            Some(ids) => ids.iter().for_each(|id| {
                slots.remove(id);
            }),
        }
    }

    /// Renames a joint's slot after an id change.
    pub fn rename(&self, old: u8, new: u8) {
        let mut slots = self.lock();
        if let Some(s) = slots.remove(&old) {
            slots.insert(new, s);
        }
    }
}
