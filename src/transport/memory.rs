//! An in-memory duplex byte pipe: [`pair`] gives the host end and the device
//! end of one line. The host's baud setting is shared with the device end, as
//! a pty's termios is readable from its master, and either end can hang the
//! line up (an unplugged adapter).

use std::collections::VecDeque;
use std::io;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use super::taken::{TakeRule, TakenCount};
use super::Transport;

/// One direction of the pipe.
#[derive(Default)]
struct Channel {
    bytes: Mutex<Queue>,
    ready: Condvar,
    /// Bytes in `bytes`, readable without the lock: a reader that only
    /// looks (a zero timeout, as the bus owner does many times while it
    /// spins for a reply) must not take the lock each time, or the writer
    /// (the simulator with that reply) loses the lock to it again and
    /// again until the spin ends.
    queued: AtomicUsize,
}

/// The bytes in one direction, and when each write of them was made
/// (its instant and how many of its bytes are still unread).
#[derive(Default)]
struct Queue {
    bytes: VecDeque<u8>,
    writes: VecDeque<(Instant, usize)>,
}

impl Queue {
    fn clear(&mut self, queued: &AtomicUsize) {
        self.bytes.clear();
        self.writes.clear();
        queued.store(0, Ordering::Release);
    }
}

/// State both ends see.
struct Line {
    to_device: Channel,
    to_host: Channel,
    baud: AtomicU32,
    hung_up: AtomicBool,
    /// What the adapter model at the device end took of the host's bytes,
    /// once it reports ([`Self`]`::reports_taken`); shared with the
    /// simulator, which can make it lie ([`TakenCount::set_stuck`]).
    taken: Arc<TakenCount>,
    taken_reported: AtomicBool,
}

/// One end of an in-memory line.
pub struct MemoryPort {
    line: Arc<Line>,
    is_host: bool,
    /// When the first byte of the last read was written by the other end.
    last_written_at: Option<Instant>,
}

/// Makes a line at `baud`: `(host end, device end)`.
pub fn pair(baud: u32) -> (MemoryPort, MemoryPort) {
    let line = Arc::new(Line {
        to_device: Channel::default(),
        to_host: Channel::default(),
        baud: AtomicU32::new(baud),
        hung_up: AtomicBool::new(false),
        taken: Arc::default(),
        taken_reported: AtomicBool::new(false),
    });
    let host = MemoryPort {
        line: line.clone(),
        is_host: true,
        last_written_at: None,
    };
    let device = MemoryPort {
        line,
        is_host: false,
        last_written_at: None,
    };
    (host, device)
}

/// Lock a channel; a poisoned lock only means another thread panicked while
/// holding plain bytes, which stay usable.
fn lock(ch: &Channel) -> MutexGuard<'_, Queue> {
    ch.bytes.lock().unwrap_or_else(|p| p.into_inner())
}

fn hangup_error() -> io::Error {
    io::Error::new(io::ErrorKind::BrokenPipe, "line hung up")
}

impl MemoryPort {
    fn outgoing(&self) -> &Channel {
        if self.is_host {
            &self.line.to_device
        } else {
            &self.line.to_host
        }
    }

    fn incoming(&self) -> &Channel {
        if self.is_host {
            &self.line.to_host
        } else {
            &self.line.to_device
        }
    }

    /// Hangs the line up (both ends see errors) or restores it.
    pub fn set_hung_up(&self, hung_up: bool) {
        self.line.hung_up.store(hung_up, Ordering::SeqCst);
        for ch in [&self.line.to_device, &self.line.to_host] {
            lock(ch).clear(&ch.queued);
            ch.ready.notify_all();
        }
        // What the unplug dropped is no longer on its way.
        self.line.taken.settle();
    }

    pub fn is_hung_up(&self) -> bool {
        self.line.hung_up.load(Ordering::SeqCst)
    }

    /// Device end, an adapter model: it reports when it takes the host's
    /// bytes ([`Self::took`]), so the host end can say what is unsent.
    pub fn reports_taken(&self) {
        self.line.taken_reported.store(true, Ordering::Release);
    }

    /// Device end: the adapter takes `bytes` more of the host's at `at`
    /// (the USB frame they leave in, perhaps still to come).
    pub fn took(&self, at: Instant, bytes: usize) {
        self.line.taken.took(at, bytes);
    }

    /// Device end, an adapter model that can say at each host write which
    /// frame takes it: the count follows the model from the write on, not
    /// from when the model's thread reads the bytes.
    pub fn take_by(&self, rule: Arc<dyn TakeRule>) {
        self.line.taken.follow(rule);
        self.reports_taken();
    }

    /// Device end, under [`Self::take_by`]: the frame decided for the
    /// first of the next `bytes` read.
    pub fn decided(&self, bytes: usize) -> Option<Instant> {
        self.line.taken.decided(bytes)
    }

    /// The line's stand-in for a driver's output count (the same on both
    /// ends), for a simulated fault to reach it.
    pub fn taken_count(&self) -> Arc<TakenCount> {
        self.line.taken.clone()
    }

    /// When the other end wrote the first byte of the last read: a pipe in
    /// memory knows, unlike a tty, whose kernel may pass bytes on late.
    pub fn take_written_at(&mut self) -> Option<Instant> {
        self.last_written_at.take()
    }
}

impl Transport for MemoryPort {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        if self.is_hung_up() {
            return Err(hangup_error());
        }
        if bytes.is_empty() {
            return Ok(());
        }
        if self.is_host {
            self.line.taken.wrote(bytes.len());
        }
        let ch = self.outgoing();
        let mut q = lock(ch);
        q.writes.push_back((Instant::now(), bytes.len()));
        q.bytes.extend(bytes);
        ch.queued.fetch_add(bytes.len(), Ordering::Release);
        drop(q);
        ch.ready.notify_all();
        Ok(())
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let deadline = Instant::now() + timeout;
        let line = self.line.clone();
        let ch = if self.is_host {
            &line.to_host
        } else {
            &line.to_device
        };
        if timeout.is_zero() && ch.queued.load(Ordering::Acquire) == 0 {
            if self.is_hung_up() {
                return Err(hangup_error());
            }
            return Ok(0);
        }
        let mut q = lock(ch);
        loop {
            if self.is_hung_up() {
                return Err(hangup_error());
            }
            if let Some(&(written_at, left)) = q.writes.front() {
                // One write at a time, so each read has one instant.
                let n = buf.len().min(left).min(q.bytes.len());
                for (dst, src) in buf.iter_mut().zip(q.bytes.drain(..n)) {
                    *dst = src;
                }
                ch.queued.fetch_sub(n, Ordering::Release);
                self.last_written_at = Some(written_at);
                match q.writes.front_mut() {
                    Some(front) if front.1 > n => front.1 -= n,
                    _ => drop(q.writes.pop_front()),
                }
                return Ok(n);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(0);
            }
            q = ch
                .ready
                .wait_timeout(q, deadline - now)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }

    fn set_baud(&mut self, baud: u32) -> io::Result<()> {
        self.line.baud.store(baud, Ordering::SeqCst);
        Ok(())
    }

    fn baud(&self) -> u32 {
        self.line.baud.load(Ordering::SeqCst)
    }

    fn discard_input(&mut self) -> io::Result<()> {
        let ch = self.incoming();
        lock(ch).clear(&ch.queued);
        Ok(())
    }

    /// Host end, with an adapter model at the device end: the host bytes it
    /// has not taken by now, as a USB-serial driver's output count.
    fn unsent(&mut self) -> Option<usize> {
        if !self.is_host || !self.line.taken_reported.load(Ordering::Acquire) {
            return None;
        }
        Some(self.line.taken.unsent(Instant::now()))
    }
}

impl std::fmt::Debug for MemoryPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MemoryPort")
            .field("end", &if self.is_host { "host" } else { "device" })
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_read_takes_one_write_and_says_when_it_was_made() {
        let (mut host, mut dev) = pair(500_000);
        let before = Instant::now();
        host.write_all(&[1, 2]).unwrap();
        std::thread::sleep(Duration::from_millis(2));
        let between = Instant::now();
        host.write_all(&[3]).unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(dev.read_timeout(&mut buf, Duration::ZERO).unwrap(), 2);
        let first = dev.take_written_at().expect("an instant");
        assert!(first >= before && first < between);
        assert_eq!(dev.read_timeout(&mut buf, Duration::ZERO).unwrap(), 1);
        assert_eq!(buf[0], 3);
        assert!(dev.take_written_at().expect("an instant") >= between);
        assert_eq!(dev.take_written_at(), None, "taken once");
        // All read: a look finds nothing, and the next write is found.
        assert_eq!(dev.read_timeout(&mut buf, Duration::ZERO).unwrap(), 0);
        host.write_all(&[4, 5]).unwrap();
        assert_eq!(dev.read_timeout(&mut buf, Duration::ZERO).unwrap(), 2);
    }

    #[test]
    fn the_host_sees_its_bytes_unsent_until_the_adapter_takes_them() {
        let (mut host, mut dev) = pair(500_000);
        host.write_all(&[1, 2, 3]).unwrap();
        assert_eq!(host.unsent(), None, "no adapter model reports");
        dev.reports_taken();
        assert_eq!(host.unsent(), Some(3));
        let mut buf = [0u8; 8];
        assert_eq!(dev.read_timeout(&mut buf, Duration::ZERO).unwrap(), 3);
        let now = Instant::now();
        dev.took(now + Duration::from_secs(3600), 3);
        assert_eq!(host.unsent(), Some(3), "taken at a frame still to come");
        host.write_all(&[4]).unwrap();
        dev.took(now, 1);
        // Reports come in order of the frames; a later one due first is
        // not seen before the earlier one.
        assert_eq!(host.unsent(), Some(4));
        dev.set_hung_up(true);
        assert_eq!(
            host.unsent(),
            Some(0),
            "an unplug drops what was on its way"
        );
        assert_eq!(dev.unsent(), None, "the device end does not ask");
    }

    #[test]
    fn bytes_cross_and_baud_is_shared() {
        let (mut host, mut dev) = pair(230_400);
        host.write_all(&[1, 2, 3]).unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(
            dev.read_timeout(&mut buf, Duration::from_millis(10))
                .unwrap(),
            3
        );
        assert_eq!(&buf[..3], &[1, 2, 3]);
        assert_eq!(
            host.read_timeout(&mut buf, Duration::from_millis(1))
                .unwrap(),
            0
        );
        host.set_baud(500_000).unwrap();
        assert_eq!(dev.baud(), 500_000);
    }

    #[test]
    fn hangup_is_an_error_on_both_ends() {
        let (mut host, dev) = pair(500_000);
        dev.set_hung_up(true);
        let mut buf = [0u8; 4];
        let err = host
            .read_timeout(&mut buf, Duration::from_millis(1))
            .unwrap_err();
        assert!(super::super::is_hangup(&err));
        // A look without waiting says so too, not "nothing yet".
        let err = host.read_timeout(&mut buf, Duration::ZERO).unwrap_err();
        assert!(super::super::is_hangup(&err));
        assert!(host.write_all(&[0]).is_err());
    }
}
