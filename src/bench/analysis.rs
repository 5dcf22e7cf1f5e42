//! What the simulator's frame log says about a run: per-joint control
//! updates and telemetry samples per second, and how long each setpoint
//! took from the client to the last byte of the frame that carried it.
//!
//! Pure: a function of the log and the client's writes.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::protocol::{Command, Frame};
use crate::sim::WireFrame;

use super::client::{write_of, Write};

/// Reply indices that are telemetry (INFO_01, INFO_02).
const TELEMETRY_INDICES: [u8; 2] = [1, 2];
/// Offset of a reply's index byte in a standard frame (can_id byte 2).
const REPLY_INDEX_AT: usize = 6;

#[derive(Debug, Clone, Default)]
pub struct Analysis {
    pub window: Duration,
    /// New targets put on the wire per second, per joint.
    pub control_hz: BTreeMap<u8, f64>,
    /// INFO_01/INFO_02 replies per second, per joint.
    pub telemetry_hz: BTreeMap<u8, f64>,
    /// Setpoint-to-wire latency of every joint-write carried, µs, sorted.
    pub latencies_us: Vec<u64>,
    /// Joint-writes the client made in the window.
    pub written: usize,
    pub broadcasts: u64,
    pub control_frames: u64,
    pub polls: u64,
    /// Idle line before each host frame, µs, sorted: after a reply (the
    /// host's reaction through two OS hops) and after a host frame.
    pub idle_after_reply_us: Vec<u64>,
    pub idle_after_host_us: Vec<u64>,
}

/// The `p`-quantile (0..=1) of sorted values.
pub fn quantile(sorted: &[u64], p: f64) -> u64 {
    let i = ((sorted.len() as f64 * p).ceil() as usize).saturating_sub(1);
    sorted.get(i).copied().unwrap_or(0)
}

impl Analysis {
    /// The `p`-quantile (0..=1) of the latencies, µs.
    pub fn latency_us(&self, p: f64) -> u64 {
        quantile(&self.latencies_us, p)
    }

    pub fn min_rate(rates: &BTreeMap<u8, f64>) -> f64 {
        rates.values().copied().fold(f64::INFINITY, f64::min)
    }

    pub fn mean_rate(rates: &BTreeMap<u8, f64>) -> f64 {
        rates.values().sum::<f64>() / rates.len().max(1) as f64
    }
}

struct Tally<'a> {
    writes: &'a [Write],
    /// The write each joint last received.
    last: BTreeMap<u8, u64>,
    updates: BTreeMap<u8, u64>,
    latencies_us: Vec<u64>,
}

impl Tally<'_> {
    /// Joint `id` received the angle `raw` in a frame ending at `end`.
    fn carried(&mut self, id: u8, raw: i16, end: Instant) {
        let Some(n) = write_of(raw) else { return };
        if self.last.insert(id, n) == Some(n) {
            return; // a broadcast slot repeating the joint's current target
        }
        *self.updates.entry(id).or_default() += 1;
        if let Some(w) = usize::try_from(n).ok().and_then(|i| self.writes.get(i)) {
            self.latencies_us
                .push(end.saturating_duration_since(w.at).as_micros() as u64);
        }
    }
}

/// Tallies the frames that ended within `from..to` on the simulated wire.
pub fn analyse(
    log: &[WireFrame],
    writes: &[Write],
    ids: &[u8],
    from: Instant,
    to: Instant,
) -> Analysis {
    let mut a = Analysis {
        window: to.saturating_duration_since(from),
        ..Analysis::default()
    };
    let mut tally = Tally {
        writes,
        last: BTreeMap::new(),
        updates: BTreeMap::new(),
        latencies_us: Vec::new(),
    };
    let mut telemetry: BTreeMap<u8, u64> = BTreeMap::new();
    idle_gaps(log, from, to, &mut a);
    for f in log
        .iter()
        .filter(|f| !f.collided && f.end >= from && f.end < to)
    {
        if f.from_host {
            host_frame(f, ids, &mut tally, &mut a);
        } else if let Some(id) = f.dev_id.filter(|id| ids.contains(id)) {
            if TELEMETRY_INDICES.contains(&f.bytes[REPLY_INDEX_AT]) {
                *telemetry.entry(id).or_default() += 1;
            }
        }
    }
    let secs = a.window.as_secs_f64().max(f64::EPSILON);
    let per_s = |m: &BTreeMap<u8, u64>| {
        ids.iter()
            .map(|id| (*id, m.get(id).copied().unwrap_or(0) as f64 / secs))
            .collect()
    };
    a.control_hz = per_s(&tally.updates);
    a.telemetry_hz = per_s(&telemetry);
    a.written = writes.iter().filter(|w| w.at >= from && w.at < to).count() * ids.len();
    tally.latencies_us.sort_unstable();
    a.latencies_us = tally.latencies_us;
    a
}

/// Idle time on the line before each host frame that started in the window.
fn idle_gaps(log: &[WireFrame], from: Instant, to: Instant, a: &mut Analysis) {
    for pair in log.windows(2) {
        let (prev, next) = (&pair[0], &pair[1]);
        if !next.from_host || next.start < from || next.start >= to {
            continue;
        }
        let gap = next.start.saturating_duration_since(prev.end).as_micros() as u64;
        if prev.from_host {
            a.idle_after_host_us.push(gap);
        } else {
            a.idle_after_reply_us.push(gap);
        }
    }
    a.idle_after_reply_us.sort_unstable();
    a.idle_after_host_us.sort_unstable();
}

/// The `p`-quantile of sorted signed values.
pub fn quantile_i64(sorted: &[i64], p: f64) -> i64 {
    let i = ((sorted.len() as f64 * p).ceil() as usize).saturating_sub(1);
    sorted.get(i).copied().unwrap_or(0)
}

fn host_frame(f: &WireFrame, ids: &[u8], tally: &mut Tally<'_>, a: &mut Analysis) {
    let Ok(cmd) = Frame::decode(&f.bytes).and_then(|fr| Command::from_frame(&fr)) else {
        return;
    };
    match cmd {
        Command::BroadcastPos(b) => {
            a.broadcasts += 1;
            for (slot, raw) in b.pos_ref.iter().enumerate() {
                let id = b.group.first_id() + slot as u8;
                if ids.contains(&id) {
                    tally.carried(id, *raw, f.end);
                }
            }
        }
        Command::Control(c) => {
            a.control_frames += 1;
            if c.op == crate::protocol::ControlOp::SetRef {
                tally.carried(c.dev_id, c.pos_ref, f.end);
            }
        }
        Command::Config(c) if c.param.is_read() => a.polls += 1,
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{
        BroadcastPos, Config, Control, Group, Info02, InfoBlock, Reply, ReplyBody,
    };

    fn frame(bytes: [u8; 20], from_host: bool, dev_id: Option<u8>, end: Instant) -> WireFrame {
        WireFrame {
            start: end - Duration::from_micros(400),
            end,
            from_host,
            dev_id,
            bytes,
            collided: false,
        }
    }

    #[test]
    fn counts_new_targets_once_and_measures_their_latency() {
        let t0 = Instant::now();
        let ms = Duration::from_millis(1);
        let writes: Vec<Write> = (0..3)
            .map(|n| Write {
                n,
                at: t0 + ms * n as u32,
            })
            .collect();
        let bc = |raw: i16| {
            Command::BroadcastPos(BroadcastPos {
                group: Group::Low,
                pos_ref: [raw, raw, 0, 0, 0, 0, 0, 0],
            })
            .encode()
        };
        let info = Reply::new(2, ReplyBody::Info02(Info02::default())).encode();
        let log = vec![
            frame(bc(1), true, None, t0 + ms * 2),
            frame(bc(1), true, None, t0 + ms * 3), // same write again: no update
            frame(
                Command::Control(Control::set_ref(1, 2, 9)).encode(),
                true,
                Some(1),
                t0 + ms * 4,
            ),
            frame(
                Command::Config(Config::read(2, InfoBlock::Info02)).encode(),
                true,
                Some(2),
                t0 + ms * 5,
            ),
            frame(info, false, Some(2), t0 + ms * 6),
        ];
        let a = analyse(&log, &writes, &[1, 2], t0, t0 + Duration::from_secs(1));
        assert_eq!(
            a.control_hz[&1], 2.0,
            "write 1 by broadcast, write 2 by control frame"
        );
        assert_eq!(a.control_hz[&2], 1.0);
        assert_eq!(a.telemetry_hz[&2], 1.0);
        assert_eq!(a.latencies_us, vec![1000, 1000, 2000]);
        assert_eq!((a.broadcasts, a.control_frames, a.polls), (2, 1, 1));
    }
}
