//! The only frames the doctor sends, and the exchange that hears what
//! comes back.
//!
//! Every frame is a read of an INFO block (SPEC §4.3, kind `read`: indexes
//! 1, 2, 12, 17, 24, 25, 32), made in [`read_frame`] and nowhere else: none
//! enables or moves a joint, none writes RAM or flash. What comes back is
//! sorted as it decodes: the reply asked for (a second one says two
//! devices share the id), a reply too early to answer this read (a late
//! one), other replies (a power-up announcement), the doctor's own frame
//! (an adapter that echoes), another host's command, and bytes that form
//! no frame (a garbled reply, noise).
//!
//! One frame at a time, each reply waited for to the end of its window:
//! the doctor measures the line, it does not race it.

use std::collections::{BTreeSet, VecDeque};
use std::io;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::bus::config::{frame_time, Timing};
use crate::bus::usb::confirm::MAX_WAITED;
use crate::protocol::{
    Command, Config, Frame, FrameBytes, InfoBlock, Message, Reply, StreamDecoder,
};
use crate::transport::adapter::AdapterModel;
use crate::transport::Transport;

/// Bytes read per system call: a few frames.
const READ_BUF: usize = 256;
/// Frames written whose echo is still recognised as the doctor's own.
const RECENT: usize = 8;
/// How long a listen that can be stopped reads before it looks again.
const LISTEN_SLICE: Duration = Duration::from_millis(10);
/// After the reply asked for, how much longer a second device with the
/// same id may take to answer too, beyond two frame times and the adapter's
/// hold: the spread of two firmwares' turnarounds.
const SECOND_REPLY_SLACK: Duration = Duration::from_millis(1);

/// Everything heard over the session besides the replies asked for.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Tally {
    /// Frames the doctor wrote.
    pub writes: u64,
    /// Those that came back byte for byte (an adapter that echoes).
    pub echoes: u64,
    /// Commands that were not the doctor's: another host on the line.
    pub foreign_commands: u64,
    /// Replies to an earlier read that came after its window closed.
    pub late_replies: u64,
    /// Replies nobody asked for (a power-up announcement, another host's).
    pub unasked_replies: u64,
}

/// What came back for one read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Heard {
    /// The reply asked for (the first, when more came).
    pub reply: Option<Reply>,
    /// From the write to that reply's decoding.
    pub after: Option<Duration>,
    /// Replies that matched: 2 or more, two devices answered.
    pub replies: u32,
    /// Bytes that formed no frame (a garbled reply, noise).
    pub garbage: u64,
    /// Frames with a valid head whose CRC failed.
    pub crc_errors: u64,
}

/// What an idle line carried while the doctor listened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Listened {
    pub bytes: u64,
    /// Device frames (power-up announcements, replies to another host).
    pub replies: u64,
    /// Host frames: another host talks on this line.
    pub commands: u64,
    /// Bytes that formed no frame.
    pub garbage: u64,
}

/// A read written: its bytes and the instant just before they were handed
/// to the port (no byte of it can be on the wire earlier).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sent {
    pub id: u8,
    pub block: InfoBlock,
    pub bytes: FrameBytes,
    pub at: Instant,
}

/// What the driver's output count did after one write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CountWatch {
    /// The port has no count (a pty, a UART, a driver without `TIOCOUTQ`).
    Unreadable,
    /// 0 at the first look after the write: it says nothing of the adapter.
    ZeroAtOnce,
    /// Fell to 0 `after` the write, at `at`.
    Fell { after: Duration, at: Instant },
    /// Still up [`MAX_WAITED`] after the write.
    NeverFell,
}

/// What one decoded frame is to the read `sent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sorted {
    /// The reply asked for.
    Answer(Reply),
    /// The same reply, decoded before this read and a reply could have
    /// crossed the wire: an earlier read's, late.
    Late,
    /// Another device's reply, or another index.
    Unasked,
    /// The read itself, back byte for byte.
    Echo,
    /// A command that is not the doctor's, or a frame that is neither.
    Foreign,
}

/// Sorts `frame` (`bytes` as they came), decoded at `now`, against the
/// read `sent` and the frames written just before it (`recent`: an echo
/// late by a whole window is still the doctor's own); `tf`: one frame's
/// time at the line's baud.
fn sort(
    sent: &Sent,
    recent: &VecDeque<FrameBytes>,
    frame: &Frame,
    bytes: &FrameBytes,
    now: Instant,
    tf: Duration,
) -> Sorted {
    match Message::from_frame(frame) {
        Ok(Message::Reply(r)) if r.dev_id == sent.id && r.index == sent.block.index() => {
            if now < sent.at + tf * 2 {
                Sorted::Late
            } else {
                Sorted::Answer(r)
            }
        }
        Ok(Message::Reply(_)) => Sorted::Unasked,
        Ok(Message::Command(_)) if *bytes == sent.bytes || recent.contains(bytes) => Sorted::Echo,
        Ok(Message::Command(_)) | Err(_) => Sorted::Foreign,
    }
}

/// The frame reading `block` of device `id`: the only frame the doctor sends.
pub(crate) fn read_frame(id: u8, block: InfoBlock) -> FrameBytes {
    Command::Config(Config::read(id, block)).encode()
}

/// The port, the decoder and the line's timing, for one session.
pub(crate) struct Exchange<'a> {
    port: &'a mut dyn Transport,
    decoder: StreamDecoder,
    adapter: AdapterModel,
    frame: Duration,
    turnaround: Duration,
    margin: Duration,
    buf: [u8; READ_BUF],
    pub(crate) tally: Tally,
    /// Ids heard in an intact reply since [`Self::take_heard_from`] (late
    /// ones and announcements included): devices at this baud.
    heard_from: BTreeSet<u8>,
    /// The last frames written, to know their echoes however late.
    recent: VecDeque<FrameBytes>,
    /// True when the run must stop (an e-stop on the bus that lent the
    /// port, or that bus stopping): checked before each write and while
    /// listening.
    stop: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl std::fmt::Debug for Exchange<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Exchange")
            .field("adapter", &self.adapter)
            .field("frame", &self.frame)
            .field("tally", &self.tally)
            .finish_non_exhaustive()
    }
}

impl<'a> Exchange<'a> {
    /// `timing`: the daemon's defaults (turnaround, reply margin).
    pub(crate) fn new(port: &'a mut dyn Transport, adapter: AdapterModel, timing: &Timing) -> Self {
        let frame = frame_time(port.baud());
        Self {
            port,
            decoder: StreamDecoder::new(),
            adapter,
            frame,
            turnaround: Duration::from_micros(timing.turnaround_us),
            margin: Duration::from_micros(timing.reply_margin_us),
            buf: [0; READ_BUF],
            tally: Tally::default(),
            heard_from: BTreeSet::new(),
            recent: VecDeque::with_capacity(RECENT),
            stop: None,
        }
    }

    /// The run stops with `Interrupted` once `stop` says so.
    pub(crate) fn stop_when(&mut self, stop: &'a (dyn Fn() -> bool + Sync)) {
        self.stop = Some(stop);
    }

    fn stopped(&self) -> io::Result<()> {
        match self.stop {
            Some(stop) if stop() => Err(io::Error::new(
                io::ErrorKind::Interrupted,
                "an e-stop was asked on the bus, or it is stopping",
            )),
            _ => Ok(()),
        }
    }

    pub(crate) fn baud(&self) -> u32 {
        self.port.baud()
    }

    pub(crate) fn adapter(&self) -> AdapterModel {
        self.adapter
    }

    /// One frame's time on the wire at the port's baud.
    pub(crate) fn frame(&self) -> Duration {
        self.frame
    }

    /// The ids heard in an intact reply since the last call.
    pub(crate) fn take_heard_from(&mut self) -> BTreeSet<u8> {
        std::mem::take(&mut self.heard_from)
    }

    /// Switches the port's baud, dropping what was read at the old one.
    pub(crate) fn set_baud(&mut self, baud: u32) -> io::Result<()> {
        self.port.set_baud(baud)?;
        self.port.discard_input()?;
        self.decoder = StreamDecoder::new();
        self.frame = frame_time(baud);
        Ok(())
    }

    /// Writes the read of `block` from `id`.
    pub(crate) fn send(&mut self, id: u8, block: InfoBlock) -> io::Result<Sent> {
        self.stopped()?;
        let bytes = read_frame(id, block);
        // Before the write: taken after it, a thread held off its CPU
        // between the two would date the write late, and its own reply
        // would then look too early to be one ([`sort`]: `Late`).
        let at = Instant::now();
        self.port.write_all(&bytes)?;
        self.tally.writes += 1;
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back(bytes);
        Ok(Sent {
            id,
            block,
            bytes,
            at,
        })
    }

    /// [`Self::send`], then [`Self::hear`].
    pub(crate) fn ask(&mut self, id: u8, block: InfoBlock) -> io::Result<Heard> {
        let sent = self.send(id, block)?;
        self.hear(&sent)
    }

    /// The latest a reply may come after its read was written, as the
    /// daemon reckons it: the wait for a USB frame, request and reply on the
    /// wire, the turnaround, the adapter's hold, the margin.
    pub(crate) fn reply_window(&self) -> Duration {
        self.adapter.write_hold()
            + self.frame * 2
            + self.turnaround
            + self.adapter.reply_hold()
            + self.margin
    }

    /// Reads until `sent`'s window closes (or shortly after its reply, the
    /// time a second device with the same id would need), sorting frames.
    pub(crate) fn hear(&mut self, sent: &Sent) -> io::Result<Heard> {
        let before = self.decoder.stats();
        let mut heard = Heard::default();
        let mut deadline = sent.at + self.reply_window();
        loop {
            self.sort_frames(sent, &mut heard, &mut deadline);
            let left = deadline.saturating_duration_since(Instant::now());
            let n = self.port.read_timeout(&mut self.buf, left)?;
            self.decoder.push(&self.buf[..n]);
            if left.is_zero() {
                // Past the window, one look at what is already there: a
                // reply that came in time is not lost to this thread having
                // been held off its CPU until the window closed.
                self.sort_frames(sent, &mut heard, &mut deadline);
                break;
            }
        }
        // What is left when the window closes formed no frame in time.
        self.decoder.clear();
        let after = self.decoder.stats();
        heard.crc_errors = after.crc_errors - before.crc_errors;
        heard.garbage = after.skipped_bytes - before.skipped_bytes;
        Ok(heard)
    }

    fn sort_frames(&mut self, sent: &Sent, heard: &mut Heard, deadline: &mut Instant) {
        while let Some((frame, bytes)) = self.decoder.next_frame_with_bytes() {
            let now = Instant::now();
            if let Frame::Standard(sf) = &frame {
                if let Some(r) = Reply::from_standard(sf) {
                    self.heard_from.insert(r.dev_id);
                }
            }
            match sort(sent, &self.recent, &frame, &bytes, now, self.frame) {
                Sorted::Answer(r) => {
                    heard.replies += 1;
                    if heard.reply.is_none() {
                        heard.reply = Some(r);
                        heard.after = Some(now.saturating_duration_since(sent.at));
                        let second =
                            self.frame * 2 + self.adapter.reply_hold() + SECOND_REPLY_SLACK;
                        *deadline = (*deadline).min(now + second);
                    }
                }
                Sorted::Late => self.tally.late_replies += 1,
                Sorted::Unasked => self.tally.unasked_replies += 1,
                Sorted::Echo => self.tally.echoes += 1,
                Sorted::Foreign => self.tally.foreign_commands += 1,
            }
        }
    }

    /// Listens for `span` without sending anything.
    pub(crate) fn listen(&mut self, span: Duration) -> io::Result<Listened> {
        let before = self.decoder.stats();
        let mut heard = Listened::default();
        let until = Instant::now() + span;
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            self.stopped()?;
            let slice = if self.stop.is_some() {
                left.min(LISTEN_SLICE)
            } else {
                left
            };
            let n = self.port.read_timeout(&mut self.buf, slice)?;
            heard.bytes += n as u64;
            self.decoder.push(&self.buf[..n]);
            while let Some(frame) = self.decoder.next_frame() {
                match Message::from_frame(&frame) {
                    Ok(Message::Reply(_)) => heard.replies += 1,
                    _ => heard.commands += 1,
                }
            }
            if n == 0 && slice == left {
                break;
            }
        }
        self.decoder.clear();
        heard.garbage = self.decoder.stats().skipped_bytes - before.skipped_bytes;
        Ok(heard)
    }

    /// Looks at the driver's output count from just after `sent` until it
    /// falls to 0, or [`MAX_WAITED`] (the daemon's longest wait) has passed.
    pub(crate) fn watch_count(&mut self, sent: &Sent) -> CountWatch {
        match self.port.unsent() {
            None => return CountWatch::Unreadable,
            Some(0) => return CountWatch::ZeroAtOnce,
            Some(_) => {}
        }
        loop {
            let now = Instant::now();
            let waited = now.saturating_duration_since(sent.at);
            match self.port.unsent() {
                None => return CountWatch::Unreadable,
                Some(0) => {
                    return CountWatch::Fell {
                        after: waited,
                        at: now,
                    }
                }
                Some(_) if waited >= MAX_WAITED => return CountWatch::NeverFell,
                // Sub-millisecond events: a sleep would round them away.
                Some(_) => std::thread::yield_now(),
            }
        }
    }
}

#[cfg(test)]
#[path = "exchange_tests.rs"]
mod tests;
