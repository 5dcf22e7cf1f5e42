//! Counters of everything the simulator saw on the line, and occupancy
//! between two snapshots.

use std::time::{Duration, Instant};

use serde::Serialize;

use crate::protocol::Command;

/// Host frames by what they carried.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FrameKinds {
    pub control: u64,
    pub jog: u64,
    pub config_read: u64,
    pub config_write: u64,
    pub broadcast_pos: u64,
    pub broadcast_spd: u64,
    pub broadcast_enable: u64,
    /// Valid CRC, but not a command (e.g. EN 4..255, a reply's can_id, a bad field).
    pub not_a_command: u64,
    /// Frames of public host programs that no table documents (the vendor
    /// SDK's enable-all and current broadcasts).
    pub vendor: u64,
}

impl FrameKinds {
    /// Counts one command by its kind.
    pub fn count(&mut self, cmd: &Command) {
        match cmd {
            Command::Control(_) => self.control += 1,
            Command::Jog(_) => self.jog += 1,
            Command::Config(c) if c.param.is_read() => self.config_read += 1,
            Command::Config(_) => self.config_write += 1,
            Command::BroadcastPos(_) => self.broadcast_pos += 1,
            Command::BroadcastSpd(_) => self.broadcast_spd += 1,
            Command::BroadcastEnableUnverified(_) => self.broadcast_enable += 1,
            Command::Vendor(_) => self.vendor += 1,
        }
    }
}

/// A snapshot of the simulator's counters at `at`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SimStats {
    #[serde(skip)]
    pub at: Instant,
    /// Line busy time up to `at` (frames plus the turnaround before replies).
    pub busy: Duration,
    /// Host frames that left the line (valid head and CRC as sent).
    pub host_frames: u64,
    pub kinds: FrameKinds,
    /// Replies and announcements delivered intact.
    pub replies: u64,
    pub announcements: u64,
    /// Noise bursts handed to the host ([`super::Fault::Noise`]).
    pub noise_bursts: u64,
    /// Bad-CRC candidates in the host's byte stream, plus host frames the
    /// corruption fault garbled on the line.
    pub crc_errors: u64,
    /// Host bytes that formed no frame.
    pub skipped_bytes: u64,
    /// Pairs of overlapping transmissions.
    pub collisions: u64,
    pub collided_host_frames: u64,
    pub collided_replies: u64,
    /// Host frames that waited behind the previous host frame.
    pub queued_ahead: u64,
    /// Frames sent at a baud the other side did not listen at: host frames
    /// some device took as garbage, device frames the host got as garbage.
    pub baud_mismatches: u64,
    /// Replies the drop fault swallowed.
    pub dropped_replies: u64,
    /// Control frames a device missed by an injected fault.
    pub missed_control_frames: u64,
    /// Replies the corruption fault garbled.
    pub corrupted_replies: u64,
    /// Reply bytes the host was not reading fast enough to take.
    pub host_overrun_bytes: u64,
    /// Host writes an adapter model found waiting after the simulator's
    /// thread had not watched the line for over 100 µs (a stall): dated to
    /// the earliest instant they may have been written.
    pub host_reads_undated: u64,
    /// Host writes a write delay (a fault) made miss the USB frame they
    /// would have made: each a chance of a collision.
    pub host_writes_slipped: u64,
    /// Host frames an echoing adapter handed back to the host.
    pub echoes: u64,
    /// The line is unplugged right now.
    pub unplugged: bool,
}

impl SimStats {
    pub fn new(at: Instant) -> Self {
        Self {
            at,
            busy: Duration::ZERO,
            host_frames: 0,
            kinds: FrameKinds::default(),
            replies: 0,
            announcements: 0,
            noise_bursts: 0,
            crc_errors: 0,
            skipped_bytes: 0,
            collisions: 0,
            collided_host_frames: 0,
            collided_replies: 0,
            queued_ahead: 0,
            baud_mismatches: 0,
            dropped_replies: 0,
            missed_control_frames: 0,
            corrupted_replies: 0,
            host_overrun_bytes: 0,
            host_reads_undated: 0,
            host_writes_slipped: 0,
            echoes: 0,
            unplugged: false,
        }
    }

    /// Fraction of the time between two snapshots the line was busy (0 when
    /// the snapshots are not in order).
    pub fn occupancy(earlier: &SimStats, later: &SimStats) -> f64 {
        let span = later.at.saturating_duration_since(earlier.at);
        if span.is_zero() {
            return 0.0;
        }
        let busy = later.busy.saturating_sub(earlier.busy);
        busy.as_secs_f64() / span.as_secs_f64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occupancy_is_busy_over_span() {
        let t0 = Instant::now();
        let a = SimStats::new(t0);
        let mut b = SimStats::new(t0 + Duration::from_millis(10));
        b.busy = Duration::from_millis(5);
        assert!((SimStats::occupancy(&a, &b) - 0.5).abs() < 1e-12);
        assert_eq!(SimStats::occupancy(&b, &a), 0.0);
    }
}
