//! The timestamped frame log: every transmission that left the line, in the
//! order it left, in a bounded ring so a long run cannot eat memory.

use std::collections::VecDeque;
use std::time::Instant;

use crate::protocol::{Command, FrameBytes};

/// One transmission as the line carried it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WireFrame {
    pub start: Instant,
    pub end: Instant,
    pub from_host: bool,
    /// The device that sent it, or the id a host frame addressed (none for
    /// broadcasts and frames that are not commands).
    pub dev_id: Option<u8>,
    /// The bytes as sent (before collision or corruption garbled them).
    pub bytes: FrameBytes,
    pub collided: bool,
}

/// The id a host command addresses (none for group broadcasts).
pub(crate) fn addressed_id(cmd: &Command) -> Option<u8> {
    match cmd {
        Command::Control(c) => Some(c.dev_id),
        Command::Jog(j) => Some(j.dev_id),
        Command::Config(c) => Some(c.dev_id),
        _ => None,
    }
}

#[derive(Debug)]
pub(crate) struct FrameLog {
    ring: VecDeque<WireFrame>,
    capacity: usize,
}

impl FrameLog {
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            ring: VecDeque::new(),
            capacity: capacity.max(1),
        }
    }

    pub(crate) fn push(&mut self, f: WireFrame) {
        if self.ring.len() == self.capacity {
            self.ring.pop_front();
        }
        self.ring.push_back(f);
    }

    pub(crate) fn snapshot(&self) -> Vec<WireFrame> {
        self.ring.iter().copied().collect()
    }

    pub(crate) fn clear(&mut self) {
        self.ring.clear();
    }
}

/// Three frames either side of each collision, one line each (µs from the
/// first frame of the log), for reading what went wrong.
pub fn collision_context(log: &[WireFrame]) -> Vec<String> {
    const SIDE: usize = 3;
    let Some(t0) = log.first().map(|f| f.start) else {
        return Vec::new();
    };
    let mut lines = Vec::new();
    for (i, _) in log.iter().enumerate().filter(|(_, f)| f.collided) {
        lines.push("  -- collision".to_string());
        for f in &log[i.saturating_sub(SIDE)..(i + SIDE + 1).min(log.len())] {
            lines.push(format!(
                "  {:>10} .. {:>10} µs  {}  {:<8}{}  {:02X?}",
                (f.start - t0).as_micros(),
                (f.end - t0).as_micros(),
                if f.from_host { "host  " } else { "device" },
                f.dev_id.map_or("-".to_string(), |id| id.to_string()),
                if f.collided { " collided" } else { "" },
                &f.bytes[..10]
            ));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_keeps_the_newest() {
        let t = Instant::now();
        let mut log = FrameLog::new(2);
        for i in 0..3u8 {
            log.push(WireFrame {
                start: t,
                end: t,
                from_host: true,
                dev_id: Some(i),
                bytes: [0; 20],
                collided: false,
            });
        }
        let ids: Vec<_> = log.snapshot().iter().map(|f| f.dev_id).collect();
        assert_eq!(ids, vec![Some(1), Some(2)]);
    }
}
