//! The pseudo-terminal's own lag, measured beside a run on its own pty.
//!
//! A byte written to a pty reaches the reader only after a kernel worker
//! (`kworker/u*`, normal priority) has moved it across. When that worker
//! is queued on a CPU busy with another process's thread it waits for the
//! thread's time slice, milliseconds, even with the other CPU idle. Behind
//! an adapter model such a wait is a write that reached the adapter late,
//! whatever the daemon did; this probe shows how late the host's ptys were
//! while the run was measured, so a run can be judged. It writes a frame's
//! worth of bytes every millisecond from a thread at the owner's priority
//! and reads them at the simulator's.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, AsRawFd};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;

use crate::protocol::FRAME_LEN;
use crate::transport::tty::{make_raw, wait_readable};

/// One write per this: the rate of a bus's transfers.
const PERIOD: Duration = Duration::from_millis(1);
/// A lag above this is counted apart: a write a whole USB frame late.
pub const LATE: Duration = Duration::from_millis(1);

/// The probe's two threads while they run.
pub(crate) struct PtyLagProbe {
    stop: Arc<AtomicBool>,
    /// Bytes read so far (for a test to wait on).
    #[cfg(test)]
    read: Arc<AtomicUsize>,
    writer: JoinHandle<io::Result<Vec<Instant>>>,
    reader: JoinHandle<io::Result<Vec<(usize, Instant)>>>,
}

/// The lag of each write, host write to reader.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PtyLag {
    pub lags: Vec<Duration>,
}

impl PtyLagProbe {
    /// Opens a pty of its own and starts writing and reading; `priorities`
    /// are the writer's and the reader's real-time priorities (0: normal).
    pub(crate) fn start(priorities: (u8, u8)) -> io::Result<Self> {
        let pty = openpty(None, None).map_err(io::Error::from)?;
        make_raw(pty.slave.as_fd(), 500_000)?;
        let flags = fcntl(pty.master.as_raw_fd(), FcntlArg::F_GETFL).map_err(io::Error::from)?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(pty.master.as_raw_fd(), FcntlArg::F_SETFL(flags)).map_err(io::Error::from)?;
        let (mut slave, mut master) = (File::from(pty.slave), File::from(pty.master));
        let stop = Arc::new(AtomicBool::new(false));
        let read = Arc::new(AtomicUsize::new(0));
        let writer = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("pty-lag-write".into())
                .spawn(move || write_frames(&mut slave, &stop, priorities.0))?
        };
        let reader = {
            let (stop, read) = (stop.clone(), read.clone());
            std::thread::Builder::new()
                .name("pty-lag-read".into())
                .spawn(move || read_frames(&mut master, &stop, &read, priorities.1))?
        };
        Ok(Self {
            stop,
            #[cfg(test)]
            read,
            writer,
            reader,
        })
    }

    /// Bytes read back so far.
    #[cfg(test)]
    fn bytes_read(&self) -> usize {
        self.read.load(Ordering::Relaxed)
    }

    /// Stops both threads and matches each write to the read that took its
    /// last byte.
    pub(crate) fn finish(self) -> io::Result<PtyLag> {
        self.stop.store(true, Ordering::Relaxed);
        let sent = joined(self.writer.join())?;
        let seen = joined(self.reader.join())?;
        Ok(PtyLag::matched(&sent, &seen))
    }
}

impl PtyLag {
    /// `sent[k]` is when write `k` (a frame's bytes) returned; `seen` the
    /// running byte total after each read and when.
    fn matched(sent: &[Instant], seen: &[(usize, Instant)]) -> Self {
        let mut lags = Vec::with_capacity(sent.len());
        let mut j = 0;
        for (k, at) in sent.iter().enumerate() {
            let end = (k + 1) * FRAME_LEN;
            while j < seen.len() && seen[j].0 < end {
                j += 1;
            }
            let Some((_, read_at)) = seen.get(j) else {
                break;
            };
            lags.push(read_at.saturating_duration_since(*at));
        }
        Self { lags }
    }

    /// The lag at quantile `p` (0 with no sample).
    pub fn quantile(&self, p: f64) -> Duration {
        let mut v = self.lags.clone();
        v.sort_unstable();
        let i = ((v.len() as f64 * p) as usize).min(v.len().saturating_sub(1));
        v.get(i).copied().unwrap_or_default()
    }

    pub fn max(&self) -> Duration {
        self.lags.iter().max().copied().unwrap_or_default()
    }

    /// Writes that took longer than [`LATE`].
    pub fn late(&self) -> usize {
        self.lags.iter().filter(|l| **l > LATE).count()
    }
}

fn joined<T>(r: std::thread::Result<io::Result<T>>) -> io::Result<T> {
    r.unwrap_or_else(|_| Err(io::Error::other("pty lag probe thread panicked")))
}

fn at_priority(priority: u8) {
    if priority > 0 {
        // Refused, the probe still measures, at normal priority.
        let _ = crate::rt::set_fifo(0, priority);
    }
}

/// Writes a frame every [`PERIOD`] until `stop`; when each write returned.
fn write_frames(slave: &mut File, stop: &AtomicBool, priority: u8) -> io::Result<Vec<Instant>> {
    at_priority(priority);
    let mut sent = Vec::new();
    let frame = [0x55u8; FRAME_LEN];
    let mut next = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        next += PERIOD;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        match slave.write_all(&frame) {
            Ok(()) => sent.push(Instant::now()),
            // The reader may end first and close the master.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => return Err(e),
        }
    }
    Ok(sent)
}

/// Reads until `stop`; the running byte total and when each read returned.
fn read_frames(
    master: &mut File,
    stop: &AtomicBool,
    read: &AtomicUsize,
    priority: u8,
) -> io::Result<Vec<(usize, Instant)>> {
    at_priority(priority);
    let mut seen = Vec::new();
    let (mut total, mut buf) = (0usize, [0u8; 256]);
    while !stop.load(Ordering::Relaxed) {
        if !wait_readable(master.as_fd(), PERIOD * 10)? {
            continue;
        }
        match master.read(&mut buf) {
            Ok(n) => {
                total += n;
                seen.push((total, Instant::now()));
                read.store(total, Ordering::Relaxed);
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            // The writer ends first and its close hangs the master up.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => return Err(e),
        }
    }
    Ok(seen)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_write_is_dated_by_the_read_that_takes_its_last_byte() {
        let t0 = Instant::now();
        let at = |us: u64| t0 + Duration::from_micros(us);
        let sent = [at(0), at(1_000), at(2_000)];
        // The first frame comes in two reads; the second and third in one, late.
        let seen = [
            (10, at(20)),
            (FRAME_LEN, at(40)),
            (3 * FRAME_LEN, at(3_500)),
        ];
        let lag = PtyLag::matched(&sent, &seen);
        let us = |d: &Duration| d.as_micros();
        assert_eq!(
            lag.lags.iter().map(us).collect::<Vec<_>>(),
            [40, 2_500, 1_500]
        );
        assert_eq!(lag.late(), 2);
        assert_eq!(lag.max(), Duration::from_micros(2_500));
        assert_eq!(lag.quantile(0.5), Duration::from_micros(1_500));
    }

    #[test]
    fn a_write_never_read_is_left_out() {
        let t0 = Instant::now();
        let lag = PtyLag::matched(&[t0, t0], &[(FRAME_LEN, t0)]);
        assert_eq!(lag.lags.len(), 1);
    }

    #[test]
    fn the_probe_reads_what_it_writes() {
        let probe = PtyLagProbe::start((0, 0)).expect("a pty");
        let deadline = Instant::now() + Duration::from_secs(30);
        while probe.bytes_read() < 3 * FRAME_LEN && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        let lag = probe.finish().expect("the probe's threads");
        assert!(lag.lags.len() >= 3, "{} writes read back", lag.lags.len());
    }
}
