//! The port and the only code that touches it: writes host frames (when the
//! scheduler's line model says so), reads and decodes what comes back,
//! matches the reply a transaction waits for and keeps the rest for the
//! owner, counts and logs every frame, and reopens the port after it was lost.

use std::io;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use crate::protocol::{Command, FrameBytes, Message, Reply, StreamDecoder, FRAME_LEN};
use crate::rt::wake::WakeLateness;
use crate::transport::adapter::{AdapterInfo, AdapterModel};
use crate::transport::{Opener, PortNote, Transport};

use super::config::{frame_time, Timing};
use super::handle::{BusCounters, BusShared, LoggedFrame};
use super::packets::{PacketEnds, PacketMark};
use super::wire::Want;

/// Bytes read per system call; a few frames.
const READ_BUF: usize = 256;
/// Wake-ups on bytes kept for the owner to take (it takes them after
/// every wait; more means nobody is taking them).
const WOKE_KEPT: usize = 64;

pub(super) struct Link {
    port: Option<Box<dyn Transport>>,
    /// Reopens a lost port; `None` when the transport was handed in, which
    /// is then probed until it answers again.
    opener: Option<Opener>,
    up: bool,
    baud: u32,
    decoder: StreamDecoder,
    buf: [u8; READ_BUF],
    tx: Vec<u8>,
    /// Wire time of one frame and of one reply (turnaround included), for
    /// the busy-time counter.
    frame: Duration,
    turnaround: Duration,
    pub counters: BusCounters,
    shared: Arc<BusShared>,
    /// Replies nobody was waiting for (power-up announcements, late
    /// replies, polls written blind).
    pub inbox: Vec<Heard>,
    /// Bytes read when the last write began: a reply whose first byte came
    /// before is no answer to it.
    read_before_write: u64,
    /// Which bytes read ended a full packet of the adapter, and when.
    pub packets: PacketEnds,
    /// When reads woke on bytes the port had been seen without just
    /// before: a USB adapter's frame boundary plus this thread's wake-up,
    /// what the frame clock learns from. Bytes found already waiting came
    /// earlier than they were read and say nothing of where a boundary is.
    woke_on_bytes: Vec<Instant>,
    /// How late this thread wakes from a timed read no bytes cut short: a
    /// measure of how late it wakes on bytes too.
    wake: WakeLateness,
}

/// A reply read, with what says which request it can answer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Heard {
    pub reply: Reply,
    /// When it was decoded.
    pub at: Instant,
    /// The adapter's full packet its byte ended, if one did.
    pub packet: Option<PacketMark>,
    /// Its first byte's place in the stream read since the port opened
    /// ([`PacketEnds::bytes_read`]): a write begun after that byte was read
    /// cannot be what it answers, however alike the reply and the answer
    /// look (a power-up announcement held by an adapter's latency timer
    /// until after a poll of the same device was written).
    pub first_byte: u64,
}

fn not_open() -> io::Error {
    io::Error::new(io::ErrorKind::NotConnected, "port is not open")
}

impl Link {
    pub(super) fn new(
        port: Option<Box<dyn Transport>>,
        opener: Option<Opener>,
        baud: u32,
        timing: &Timing,
        shared: Arc<BusShared>,
    ) -> Self {
        Self {
            port,
            opener,
            up: false,
            baud,
            decoder: StreamDecoder::new(),
            buf: [0; READ_BUF],
            tx: Vec::with_capacity(FRAME_LEN * 32),
            frame: frame_time(baud),
            turnaround: Duration::from_micros(timing.turnaround_us),
            counters: BusCounters::default(),
            shared,
            inbox: Vec::new(),
            read_before_write: 0,
            packets: PacketEnds::default(),
            woke_on_bytes: Vec::new(),
            wake: WakeLateness::default(),
        }
    }

    pub(super) fn is_up(&self) -> bool {
        self.up
    }

    pub(super) fn baud(&self) -> u32 {
        self.baud
    }

    /// Opens (or, for a handed-in transport, probes) the port.
    pub(super) fn open(&mut self) -> io::Result<Vec<PortNote>> {
        let notes = match self.opener.as_mut() {
            Some(open) => {
                let (port, notes) = open(self.baud)?;
                self.port = Some(port);
                notes
            }
            None => {
                let port = self.port.as_mut().ok_or_else(not_open)?;
                port.read_timeout(&mut self.buf, std::time::Duration::ZERO)?;
                // No tty to look at: the config's adapter, if it names one,
                // still says how the bytes travel.
                vec![PortNote::Adapter(AdapterInfo {
                    model: AdapterModel::Native,
                    found_by: "a transport handed in, no tty to look at".into(),
                    tty_without_usb: false,
                    usb: false,
                })]
            }
        };
        if let Some(port) = self.port.as_mut() {
            // What a previous owner or a glitch left in the buffer is not ours.
            port.discard_input()?;
        }
        self.decoder.clear();
        self.packets.reset();
        self.up = true;
        Ok(notes)
    }

    /// Marks the port lost; a reopenable port is closed.
    pub(super) fn close(&mut self) {
        self.up = false;
        if self.opener.is_some() {
            self.port = None;
        }
    }

    /// Runs `f` on the open port; nothing when it is not open.
    pub(super) fn with_port(&mut self, f: impl FnOnce(&mut dyn Transport)) {
        if let Ok(port) = self.port() {
            f(port.as_mut());
        }
    }

    fn port(&mut self) -> io::Result<&mut Box<dyn Transport>> {
        match (self.up, self.port.as_mut()) {
            (true, Some(port)) => Ok(port),
            _ => Err(not_open()),
        }
    }

    /// Bytes written that the adapter has not taken yet, where the port
    /// can tell ([`Transport::unsent`]).
    pub(super) fn unsent(&mut self) -> Option<usize> {
        self.port().ok()?.unsent()
    }

    /// Hands `cmds` to the port back to back; returns when it handed them.
    pub(super) fn send(&mut self, cmds: &[Command]) -> io::Result<Instant> {
        self.tx.clear();
        for cmd in cmds {
            self.tx.extend_from_slice(&cmd.encode());
        }
        self.read_before_write = self.packets.bytes_read();
        match (self.up, self.port.as_mut()) {
            (true, Some(port)) => port.write_all(&self.tx)?,
            _ => return Err(not_open()),
        }
        let handed = Instant::now();
        let n = cmds.len() as u32;
        self.counters.wire_busy_us += (self.frame * n).as_micros() as u64;
        for (cmd, bytes) in cmds.iter().zip(self.tx.chunks_exact(FRAME_LEN)) {
            count_tx(&mut self.counters, cmd);
            if let Ok(bytes) = bytes.try_into() {
                self.log(true, bytes);
            }
        }
        Ok(handed)
    }

    /// Reads until `want` arrives or `deadline` passes. Other replies go to
    /// the inbox. With `want` = `None` this is an idle wait that listens.
    pub(super) fn wait(
        &mut self,
        want: Option<Want>,
        deadline: Instant,
    ) -> io::Result<Option<(Reply, Instant)>> {
        loop {
            if let Some(found) = self.take_decoded(want) {
                return Ok(Some(found));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            // A look first: bytes a blocking read wakes on date a boundary
            // only if the port was empty as it began.
            let n = self.read(Duration::ZERO)?;
            if n > 0 {
                self.pushed(n);
                continue;
            }
            let wait = deadline.saturating_duration_since(Instant::now());
            let n = self.read(wait)?;
            let returned = Instant::now();
            if n > 0 {
                if self.woke_on_bytes.len() == WOKE_KEPT {
                    self.woke_on_bytes.remove(0);
                }
                self.woke_on_bytes.push(returned);
            } else if returned >= deadline && !wait.is_zero() {
                self.wake.observe(deadline, returned);
            }
            self.pushed(n);
        }
    }

    /// The wake-ups on bytes since the last call ([`Self::woke_on_bytes`]).
    pub(super) fn take_woke_on_bytes(&mut self) -> std::vec::Drain<'_, Instant> {
        self.woke_on_bytes.drain(..)
    }

    /// How late this thread wakes from a timed read (a high quantile):
    /// bytes it wakes on are seen about that late.
    pub(super) fn wake_lateness(&self) -> Duration {
        self.wake.lead()
    }

    /// One look at the port without waiting.
    pub(super) fn poll_now(&mut self, want: Option<Want>) -> io::Result<Option<(Reply, Instant)>> {
        let n = self.read(Duration::ZERO)?;
        self.pushed(n);
        Ok(self.take_decoded(want))
    }

    /// One read into the buffer, waiting up to `timeout` for bytes.
    fn read(&mut self, timeout: Duration) -> io::Result<usize> {
        match (self.up, self.port.as_mut()) {
            (true, Some(port)) => port.read_timeout(&mut self.buf, timeout),
            _ => Err(not_open()),
        }
    }

    /// `n` bytes were read into the buffer: to the decoder, and counted.
    fn pushed(&mut self, n: usize) {
        if n > 0 {
            self.decoder.push(&self.buf[..n]);
            self.packets.read(n, Instant::now);
        }
    }

    /// Decodes buffered bytes; returns the wanted reply if it is among them.
    fn take_decoded(&mut self, want: Option<Want>) -> Option<(Reply, Instant)> {
        let mut found = None;
        while let Some((frame, bytes)) = self.decoder.next_frame_with_bytes() {
            let at = Instant::now();
            self.log(false, &bytes);
            self.counters.frames_rx += 1;
            // A command is our own frame echoed by an adapter: not a reply.
            let Ok(Message::Reply(reply)) = Message::from_frame(&frame) else {
                continue;
            };
            self.counters.wire_busy_us += (self.turnaround + self.frame).as_micros() as u64;
            let pending = self.decoder.pending();
            let heard = Heard {
                reply,
                at,
                packet: self.packets.reply(pending),
                first_byte: self.first_byte(pending),
            };
            let wanted = want.is_some_and(|w| w.dev_id == reply.dev_id && w.index == reply.index)
                && heard.first_byte >= self.read_before_write;
            if wanted {
                // The last of the wanted block read together answers: one
                // before it was on the wire before the request (see
                // `UsbPipeline::take`), and goes to the inbox.
                if let Some(earlier) = found.replace(heard) {
                    self.inbox.push(earlier);
                }
            } else {
                self.inbox.push(heard);
            }
        }
        let stats = self.decoder.stats();
        self.counters.crc_errors = stats.crc_errors;
        self.counters.skipped_bytes = stats.skipped_bytes;
        found.map(|h| (h.reply, h.at))
    }

    /// Where the first byte of a frame just decoded, `pending` bytes before
    /// the end of what was read, sits in the stream.
    fn first_byte(&self, pending: usize) -> u64 {
        self.packets
            .bytes_read()
            .saturating_sub((pending + FRAME_LEN) as u64)
    }

    /// Bytes read since the port opened when the last write began: a
    /// reply whose [`Heard::first_byte`] comes before is no answer to it.
    pub(super) fn read_before_write(&self) -> u64 {
        self.read_before_write
    }

    /// Changes the port's speed (after the devices switched), dropping what
    /// was read at the old one.
    pub(super) fn set_baud(&mut self, baud: u32) -> io::Result<()> {
        let port = self.port()?;
        port.set_baud(baud)?;
        port.discard_input()?;
        self.decoder.clear();
        self.baud = baud;
        self.frame = frame_time(baud);
        Ok(())
    }

    fn log(&self, tx: bool, bytes: &FrameBytes) {
        self.shared.log_frame(LoggedFrame {
            at: SystemTime::now(),
            tx,
            bytes: *bytes,
        });
    }
}

fn count_tx(c: &mut BusCounters, cmd: &Command) {
    match cmd {
        Command::BroadcastPos(_) | Command::BroadcastSpd(_) => c.frames_tx_broadcast += 1,
        Command::BroadcastEnableUnverified(_) => c.frames_tx_broadcast += 1,
        // Never built by the daemon; counted where it would go on the wire.
        Command::Vendor(v) => match v.is_broadcast() {
            true => c.frames_tx_broadcast += 1,
            false => c.frames_tx_control += 1,
        },
        Command::Control(_) => c.frames_tx_control += 1,
        Command::Jog(_) => c.frames_tx_jog += 1,
        Command::Config(_) => c.frames_tx_config += 1,
    }
}

#[cfg(test)]
#[path = "link_tests.rs"]
mod tests;
