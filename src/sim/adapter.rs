//! A USB-RS485 adapter between the host's tty and the simulated wire: the
//! line the runner sees delays bytes the way the chip and the USB bus do.
//! The referee keeps judging the true wire: host bytes enter it when the
//! adapter lets them out, device bytes leave it when the engine says.
//!
//! # The models (`jointd sim --adapter`, [`AdapterModel`])
//! - `native`: no adapter; the runner uses the line as it is (byte for
//!   byte the simulator without adapters).
//! - `ftdi[:MS]` (FT232R/FT231X, USB full speed): the host's bytes go out
//!   in the next 1 ms USB frame; received bytes wait in the chip until 62
//!   are buffered (a 64-byte packet less the two status bytes) or the
//!   latency timer (16 ms by default) has run since the first of them
//!   arrived, then reach the host in the next frame: a full packet of
//!   exactly 62, timed by its 62nd byte, the rest waiting for the next.
//!   Each byte is taken to have come in a byte time after the one before. Source: FTDI
//!   application note AN232B-04 "Data Throughput, Latency and
//!   Handshaking" (the timer is read here as running from the first byte
//!   buffered, the case of a short reply on an idle chip).
//! - `ch340`, `cp2102` (full speed, no settable timer): received bytes reach
//!   the host in the next 1 ms frame; host bytes go out in the next frame.
//!   Source: WCH CH340 and Silicon Labs CP2102 data sheets (bulk endpoints
//!   polled once per frame by the host controller).
//! - `ft232h[:MS]` (USB high speed): as `ftdi` with 125 µs microframes
//!   (FTDI FT232H data sheet; its latency timer works as on the FT232R).
//!
//! # Assumptions
//! - The USB frame clock is not the host's: its phase is a fixed offset
//!   from the simulator's seed, reproducible, and unknown to the daemon.
//! - A host write reaches the wire whole in the frame after it was made
//!   (bulk OUT of up to 19 × 64 bytes per full-speed frame: ample for a few
//!   frames).
//! - Nothing is lost or reordered; only held.
//! - When a host write was made is known only as well as this thread was
//!   watching the line: a read that blocked and woke on the bytes dates
//!   them to its wake-up; bytes found waiting after the thread was busy
//!   elsewhere (a stall of the machine) were written at some instant since
//!   it last saw the line empty. They are dated to the earliest of those
//!   instants: the frame the host aimed at if it wrote in time, and the
//!   earlier of two frames if it wrote too early, which is the mistake a
//!   collision should show. An in-memory line says when each write was
//!   made, and that is used instead: there the frame that takes a write is
//!   decided at the write, so the host's stand-in for a driver's output
//!   count ([`crate::transport::taken`]) falls at that frame however late
//!   this thread reads the bytes, as a driver's falls when the transfer
//!   completes. Such reads are counted
//!   ([`SimStats::host_reads_undated`](super::stats::SimStats)): a run where
//!   they coincide with collisions was judged with less precision.

use std::collections::VecDeque;
use std::io;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::transport::adapter::AdapterModel;
use crate::transport::taken::TakeRule;

use super::line::Line;
use super::rng::Rng;
use super::usb_clock::{RxRule, UsbClock};
use super::write_delay::WriteDelayCell;

/// A read that returns sooner than this after it was called did not wait:
/// its bytes were already there.
const READ_BLOCKED: Duration = Duration::from_micros(20);
/// Bytes found waiting after the line went unwatched this long are
/// counted as undated (their stamp may be off by that much).
const UNDATED_AFTER: Duration = Duration::from_micros(100);

/// Device bytes held in the chip, each with the instant it came in.
#[derive(Debug, Default)]
struct Held {
    bytes: Vec<u8>,
    times: Vec<Instant>,
    release: Option<Instant>,
}

/// The runner's line seen through an adapter model.
pub(crate) struct AdapterLine {
    inner: Box<dyn Line>,
    clock: UsbClock,
    rx: RxRule,
    /// Host bytes on their way to the wire, by the USB frame that takes
    /// them (bytes written after a frame began wait for the next one, even
    /// if this thread gets to them late).
    to_wire: VecDeque<(Instant, Vec<u8>)>,
    /// Device bytes waiting in the chip for the host.
    to_host: Held,
    /// Bytes read from the host and not yet on the wire.
    scratch: Vec<u8>,
    read_at: Option<Instant>,
    /// The last instant the host's side was seen empty.
    seen_empty: Option<Instant>,
    /// Reads whose bytes had waited unwatched (see the module doc).
    undated: u64,
    /// Which frame takes a host write (shared with a line that runs it at
    /// the host's write: [`Line::taken_at`]).
    taking: Arc<Taking>,
}

/// The chip's rule for the frame that takes a host write.
#[derive(Debug)]
pub(crate) struct Taking {
    clock: UsbClock,
    state: Mutex<TakingState>,
}

#[derive(Debug)]
struct TakingState {
    /// Host writes held on their way to the chip (a busy host or hub).
    delay: WriteDelayCell,
    dice: Rng,
    /// The frame the last host write left in: a later write never overtakes it.
    last_release: Option<Instant>,
    /// Writes the delay made miss the frame they would have made.
    slipped: u64,
}

impl Taking {
    fn state(&self) -> MutexGuard<'_, TakingState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn take_slipped(&self) -> u64 {
        std::mem::take(&mut self.state().slipped)
    }
}

impl TakeRule for Taking {
    /// The frame that takes host bytes written at `at`: the next one after
    /// they reach the chip (late by the write delay in force), and never
    /// one before the last write's.
    fn release_of(&self, at: Instant) -> Instant {
        let mut st = self.state();
        let on_time = self.clock.next_after(at);
        let reach = match st.delay.get() {
            Some(delay) => at + delay.quantile(st.dice.unit()),
            None => at,
        };
        let release = self
            .clock
            .next_after(reach)
            .max(st.last_release.unwrap_or(on_time));
        st.slipped += u64::from(release > on_time);
        st.last_release = Some(release);
        release
    }
}

impl AdapterLine {
    pub(crate) fn new(
        inner: Box<dyn Line>,
        model: AdapterModel,
        start: Instant,
        seed: u64,
        delay: WriteDelayCell,
    ) -> Self {
        let period = model.usb_frame().unwrap_or(Duration::from_millis(1));
        // The frame phase: from the seed, reproducible, unknown to the host.
        let phase = Duration::from_nanos(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) % 1_000_000);
        let clock = UsbClock::new(start, period, phase);
        let taking = Arc::new(Taking {
            clock,
            state: Mutex::new(TakingState {
                delay,
                dice: Rng::new(seed ^ 0xD17E_DE1A),
                last_release: None,
                slipped: 0,
            }),
        });
        let mut inner = inner;
        inner.reports_taken(taking.clone());
        Self {
            inner,
            clock,
            rx: RxRule::of(model),
            to_wire: VecDeque::new(),
            to_host: Held::default(),
            scratch: vec![0; 4096],
            read_at: None,
            seen_empty: None,
            undated: 0,
            taking,
        }
    }

    /// When host bytes read by a call made at `called` that returned at
    /// `returned` were written: at the wake-up if the call waited for them,
    /// else the earliest instant since the line was last seen empty.
    fn written_at(&mut self, called: Instant, returned: Instant) -> Instant {
        let seen_empty = self.seen_empty.replace(returned);
        if returned.duration_since(called) >= READ_BLOCKED {
            return returned;
        }
        let Some(empty) = seen_empty else {
            return returned;
        };
        if returned.duration_since(empty) > UNDATED_AFTER {
            self.undated += 1;
        }
        empty
    }

    /// The `n` host bytes in `scratch`, read by a call made at `called`
    /// that returned at `returned`, wait for the USB frame that takes them.
    fn queue_for_wire(&mut self, n: usize, called: Instant, returned: Instant) {
        let written = self.inner.take_written_at();
        // Decided at the host's write where the line can (as the count the
        // host reads was), else now.
        let release = match self.inner.taken_at(n) {
            Some(release) => release,
            None => {
                let at = written.unwrap_or_else(|| self.written_at(called, returned));
                let release = self.taking.release_of(at);
                self.inner.took(release, n);
                release
            }
        };
        match self.to_wire.back_mut() {
            // Written before that frame began: it takes them too.
            Some((r, bytes)) if *r == release => bytes.extend_from_slice(&self.scratch[..n]),
            _ => self
                .to_wire
                .push_back((release, self.scratch[..n].to_vec())),
        }
    }

    /// Hands the chip's held bytes to the host, a packet at a time, as
    /// their time comes.
    fn flush_to_host(&mut self, now: Instant) -> io::Result<()> {
        while self.to_host.release.is_some_and(|r| r <= now) {
            let n = self.rx.packet(self.to_host.bytes.len());
            let packet: Vec<u8> = self.to_host.bytes.drain(..n).collect();
            self.to_host.times.drain(..n);
            // A second full packet due by then goes too (each round
            // takes at least a byte).
            self.to_host.release = self.rx.release(&self.clock, &self.to_host.times);
            // The host side of a pty takes what fits; the runner counts no overrun here.
            self.inner.write(&packet)?;
        }
        Ok(())
    }

    /// How long one byte takes on the wire at the line's speed (zero when
    /// the line has none).
    fn byte_time(&self) -> Duration {
        self.inner.host_baud().map_or(Duration::ZERO, |baud| {
            Duration::from_nanos(10_000_000_000 / u64::from(baud.max(1)))
        })
    }
}

impl Line for AdapterLine {
    /// Host bytes come out when the adapter has put them on the wire: at
    /// the frame after they were written.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let deadline = Instant::now() + timeout;
        loop {
            let now = Instant::now();
            self.flush_to_host(now)?;
            if let Some((release, bytes)) = self.to_wire.front_mut().filter(|(r, _)| *r <= now) {
                // On the wire at the frame boundary, not when this thread got here.
                self.read_at = Some(*release);
                let n = bytes.len().min(buf.len());
                buf[..n].copy_from_slice(&bytes[..n]);
                bytes.drain(..n);
                if bytes.is_empty() {
                    self.to_wire.pop_front();
                }
                return Ok(n);
            }
            // Wake for whichever comes first: the deadline, bytes on their
            // way to the wire or to the host.
            let to_wire = self.to_wire.front().map(|(r, _)| *r);
            let wake = [Some(deadline), to_wire, self.to_host.release]
                .into_iter()
                .flatten()
                .min()
                .unwrap_or(deadline);
            let called = Instant::now();
            let n = self
                .inner
                .read_timeout(&mut self.scratch, wake.saturating_duration_since(now))?;
            let returned = Instant::now();
            if n > 0 {
                self.queue_for_wire(n, called, returned);
                continue;
            }
            self.seen_empty = Some(returned);
            if Instant::now() >= deadline {
                self.flush_to_host(Instant::now())?;
                return Ok(0);
            }
        }
    }

    /// Device bytes go into the chip; they reach the host by the model's rule.
    /// The bytes are written when the last of them has come off the wire:
    /// each came in a byte time after the one before it.
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let now = Instant::now();
        let byte = self.byte_time();
        let previous = self.to_host.times.last().copied();
        for k in (0..bytes.len()).rev() {
            let at = now.checked_sub(byte * k as u32).unwrap_or(now);
            self.to_host.times.push(previous.map_or(at, |p| at.max(p)));
        }
        self.to_host.bytes.extend_from_slice(bytes);
        self.to_host.release = self.rx.release(&self.clock, &self.to_host.times);
        self.flush_to_host(now)?;
        Ok(bytes.len())
    }

    fn host_baud(&self) -> Option<u32> {
        self.inner.host_baud()
    }

    fn unplug(&mut self) -> io::Result<()> {
        self.to_wire.clear();
        self.to_host = Held::default();
        self.inner.unplug()
    }

    fn replug(&mut self) -> io::Result<()> {
        self.inner.replug()
    }

    fn is_unplugged(&self) -> bool {
        self.inner.is_unplugged()
    }

    fn path(&self) -> Option<&Path> {
        self.inner.path()
    }

    fn taken_count(&self) -> Option<Arc<crate::transport::taken::TakenCount>> {
        self.inner.taken_count()
    }

    fn take_read_at(&mut self) -> Option<Instant> {
        self.read_at.take()
    }

    fn take_undated_reads(&mut self) -> u64 {
        std::mem::take(&mut self.undated)
    }

    fn take_slipped_writes(&mut self) -> u64 {
        self.taking.take_slipped()
    }

    fn next_release(&self) -> Option<Instant> {
        self.to_host.release
    }

    fn flush_due(&mut self, now: Instant) -> io::Result<()> {
        self.flush_to_host(now)
    }
}

#[cfg(test)]
#[path = "adapter_tests.rs"]
mod tests;
