//! An in-memory duplex byte pipe: [`pair`] gives the host end and the device
//! end of one line. The host's baud setting is shared with the device end, as
//! a pty's termios is readable from its master, and either end can hang the
//! line up (an unplugged adapter).

use std::collections::VecDeque;
use std::io;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use super::Transport;

/// One direction of the pipe.
#[derive(Default)]
struct Channel {
    bytes: Mutex<VecDeque<u8>>,
    ready: Condvar,
}

/// State both ends see.
struct Line {
    to_device: Channel,
    to_host: Channel,
    baud: AtomicU32,
    hung_up: AtomicBool,
}

/// One end of an in-memory line.
pub struct MemoryPort {
    line: Arc<Line>,
    is_host: bool,
}

/// Makes a line at `baud`: `(host end, device end)`.
pub fn pair(baud: u32) -> (MemoryPort, MemoryPort) {
    let line = Arc::new(Line {
        to_device: Channel::default(),
        to_host: Channel::default(),
        baud: AtomicU32::new(baud),
        hung_up: AtomicBool::new(false),
    });
    let host = MemoryPort {
        line: line.clone(),
        is_host: true,
    };
    let device = MemoryPort {
        line,
        is_host: false,
    };
    (host, device)
}

/// Lock a channel; a poisoned lock only means another thread panicked while
/// holding plain bytes, which stay usable.
fn lock(ch: &Channel) -> MutexGuard<'_, VecDeque<u8>> {
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
            lock(ch).clear();
            ch.ready.notify_all();
        }
    }

    pub fn is_hung_up(&self) -> bool {
        self.line.hung_up.load(Ordering::SeqCst)
    }
}

impl Transport for MemoryPort {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        if self.is_hung_up() {
            return Err(hangup_error());
        }
        let ch = self.outgoing();
        lock(ch).extend(bytes);
        ch.ready.notify_all();
        Ok(())
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let deadline = Instant::now() + timeout;
        let ch = self.incoming();
        let mut q = lock(ch);
        loop {
            if self.is_hung_up() {
                return Err(hangup_error());
            }
            if !q.is_empty() {
                let n = buf.len().min(q.len());
                for (dst, src) in buf.iter_mut().zip(q.drain(..n)) {
                    *dst = src;
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
        lock(self.incoming()).clear();
        Ok(())
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
        assert!(host.write_all(&[0]).is_err());
    }
}
