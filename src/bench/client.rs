//! The bench's client: streams targets for every joint at a fixed rate, as
//! a WebSocket teleoperation client would, and remembers when each write
//! was accepted. Each write's angle encodes its count so the
//! frame that carried it can be found on the simulated wire.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::bus::{BusHandle, Setpoint};

/// Thread name (the CPU report charges it to the client, not the daemon).
pub const CLIENT_THREAD: &str = "bench-client";
/// Speed limit the client asks for: 20000 rpm, the vendor's recommended maximum.
pub const SPEED_LIMIT_RAW: i16 = 13_106;
/// Writes the angle ramp can tell apart before it wraps: 30 s at 1 kHz.
pub const RAMP_STEPS: u64 = 30_000;

/// The angle (raw Q7) of the client's `n`th write: a ramp up from 0° at one
/// raw step (1/128°) per write, 7.8°/s at 1 kHz, within ±255°.
pub fn angle_of(n: u64) -> i16 {
    (n % RAMP_STEPS) as i16
}

/// The write whose angle is `raw`, among the first [`RAMP_STEPS`].
pub fn write_of(raw: i16) -> Option<u64> {
    u64::try_from(raw).ok()
}

/// One write: the client's count (encoded in its angle) and when it was made.
#[derive(Debug, Clone, Copy)]
pub struct Write {
    pub n: u64,
    pub at: Instant,
}

#[derive(Debug)]
pub struct Client {
    stop: Arc<AtomicBool>,
    join: JoinHandle<Vec<Write>>,
}

impl Client {
    /// Starts streaming targets for `ids` every `period`, at real-time
    /// `priority` unless 0.
    pub fn start(
        bus: BusHandle,
        ids: Vec<u8>,
        period: Duration,
        priority: u8,
    ) -> std::io::Result<Client> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let join = std::thread::Builder::new()
            .name(CLIENT_THREAD.into())
            .spawn(move || {
                if priority > 0 {
                    // Best effort: the bench reports whether it got it.
                    let _ = crate::rt::set_fifo(0, priority);
                }
                stream(&bus, &ids, period, &flag)
            })?;
        Ok(Client { stop, join })
    }

    /// Stops and returns every write made.
    pub fn finish(self) -> Vec<Write> {
        self.stop.store(true, Ordering::Release);
        self.join.join().unwrap_or_default()
    }
}

fn stream(bus: &BusHandle, ids: &[u8], period: Duration, stop: &AtomicBool) -> Vec<Write> {
    crate::rt::precise_timers();
    let mut writes = Vec::new();
    let mut pacer = Pacer::new(period);
    let mut targets: Vec<(u8, Setpoint)> = Vec::with_capacity(ids.len());
    while !stop.load(Ordering::Acquire) {
        let n = writes.len() as u64;
        let sp = Setpoint {
            pos_ref: angle_of(n),
            spd_ref: SPEED_LIMIT_RAW,
        };
        targets.clear();
        targets.extend(ids.iter().map(|id| (*id, sp)));
        let at = Instant::now();
        bus.set_targets_as(&targets, crate::bus::Source::Bench);
        writes.push(Write { n, at });
        pacer.wait();
    }
    writes
}

/// Paces a loop to absolute deadlines one period apart; a late iteration
/// starts the schedule over instead of bursting to catch up.
#[derive(Debug)]
pub struct Pacer {
    period: Duration,
    next: Instant,
}

impl Pacer {
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            next: Instant::now(),
        }
    }

    /// Sleeps until the next deadline.
    pub fn wait(&mut self) {
        self.next += self.period;
        let now = Instant::now();
        if self.next > now {
            std::thread::sleep(self.next - now);
        } else {
            self.next = now;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_encode_the_write_count() {
        for n in [0, 1, 2, 777, RAMP_STEPS - 1] {
            assert_eq!(write_of(angle_of(n)), Some(n));
        }
        assert_eq!(write_of(-5), None, "negative angles are not ours");
    }
}
