//! A bus as a front-end sees it: read only. Every write (motion, a
//! config, a scan, the baud, an id) is a call on the core; a front-end
//! holds nothing that could make one behind its back.

use std::sync::Arc;

use tokio::sync::{broadcast, watch};

use crate::bus::handle::{BusEvent, Commanded, LoggedFrame, WireAck};
use crate::bus::owed::OwedLimits;
use crate::bus::{BusHandle, BusSnapshot};

/// One bus, read only (cheap to clone: the handle's `Arc`).
#[derive(Debug, Clone)]
pub struct BusReader(BusHandle);

impl BusReader {
    pub(crate) fn new(bus: &BusHandle) -> Self {
        Self(bus.clone())
    }

    pub fn name(&self) -> &str {
        self.0.name()
    }

    /// What the owner published last.
    pub fn snapshot(&self) -> Arc<BusSnapshot> {
        self.0.snapshot()
    }

    /// Every snapshot the owner publishes from now on.
    pub fn watch(&self) -> watch::Receiver<Arc<BusSnapshot>> {
        self.0.watch()
    }

    /// The bus's events (resets, faults, e-stops, ...).
    pub fn events(&self) -> broadcast::Receiver<BusEvent> {
        self.0.events()
    }

    /// Which setpoint write went out on the wire last.
    pub fn wire_acks(&self) -> watch::Receiver<WireAck> {
        self.0.wire_acks()
    }

    /// Every frame on the wire from now on (a recording's, the ROS 2 bridge's tap).
    pub fn frame_tap(&self) -> broadcast::Receiver<LoggedFrame> {
        self.0.shared().frame_tap.subscribe()
    }

    /// Every setpoint write from now on, whoever wrote it (the live
    /// Foxglove view's tap; a recording taps the handle itself).
    pub fn setpoint_tap(&self) -> broadcast::Receiver<Commanded> {
        self.0.shared().setpoints.subscribe()
    }

    /// The latest `n` frames on the wire, oldest first.
    pub fn recent_frames(&self, n: usize) -> Vec<LoggedFrame> {
        self.0.recent_frames(n)
    }

    /// Current limits a routine could not write back yet.
    pub fn owed_limits(&self) -> &OwedLimits {
        self.0.owed_limits()
    }
}
