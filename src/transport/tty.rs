//! A tty opened raw (8N1, no flow control, no echo) at a given baud: a USB
//! RS-485 adapter or the slave side of a pseudo-terminal, opened the same way.
//!
//! Reads wait with `ppoll(2)`, whose timeout has nanosecond resolution (plain
//! `poll(2)` rounds to milliseconds, longer than two frames at 500000 baud).
//!
//! A bus's port is opened *exclusive*: an advisory `flock(2)` on the tty,
//! taken before the port is touched (termios, RS-485 mode, low latency),
//! held as long as the port is open. A second jointd on the same bus, or
//! `jointd doctor`, then finds it held ([`PortHeld`]) and leaves it alone.
//! `flock` rather than `TIOCEXCL`: root ignores `TIOCEXCL`, and it is what
//! other serial tools ask for too (pyserial's `exclusive=True`).

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use nix::sys::termios::{self, BaudRate, ControlFlags, FlushArg, SetArg, SpecialCharacterIndices};

use super::taken::TakenCount;
use super::{Opener, Transport};

/// The baud rates of SPEC §1 and their termios constants.
const BAUDS: [(u32, BaudRate); 5] = [
    (500_000, BaudRate::B500000),
    (230_400, BaudRate::B230400),
    (115_200, BaudRate::B115200),
    (38_400, BaudRate::B38400),
    (19_200, BaudRate::B19200),
];

fn to_termios_baud(baud: u32) -> io::Result<BaudRate> {
    BAUDS
        .iter()
        .find(|(b, _)| *b == baud)
        .map(|(_, r)| *r)
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("baud {baud} is not one the modules speak (500000, 230400, 115200, 38400, 19200)"),
            )
        })
}

/// Puts a tty in raw 8N1 mode at `baud`, reads returning whatever is there.
pub fn make_raw(fd: BorrowedFd<'_>, baud: u32) -> io::Result<()> {
    let speed = to_termios_baud(baud)?;
    let mut t = termios::tcgetattr(fd)?;
    termios::cfmakeraw(&mut t);
    t.control_flags |= ControlFlags::CLOCAL | ControlFlags::CREAD;
    t.control_flags &= !(ControlFlags::CSTOPB | ControlFlags::PARENB | ControlFlags::CRTSCTS);
    t.control_chars[SpecialCharacterIndices::VMIN as usize] = 0;
    t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
    termios::cfsetspeed(&mut t, speed)?;
    termios::tcsetattr(fd, SetArg::TCSANOW, &t)?;
    Ok(())
}

/// The output baud a tty is set to, if it is one of SPEC §1's. On a pty
/// master this reads the slave's setting (Linux routes termios ioctls of a
/// master to its slave), which is how the simulator learns the host's baud.
pub fn read_baud(fd: BorrowedFd<'_>) -> io::Result<Option<u32>> {
    let t = termios::tcgetattr(fd)?;
    let speed = termios::cfgetospeed(&t);
    Ok(BAUDS.iter().find(|(_, r)| *r == speed).map(|(b, _)| *b))
}

/// Waits until `fd` is readable or `timeout` passes. `Ok(false)` on timeout;
/// a hang-up with nothing left to read is an error.
pub fn wait_readable(fd: BorrowedFd<'_>, timeout: Duration) -> io::Result<bool> {
    let mut pfd = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask.
    let n = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if n < 0 {
        let e = io::Error::last_os_error();
        return if e.kind() == io::ErrorKind::Interrupted {
            Ok(false)
        } else {
            Err(e)
        };
    }
    if n == 0 {
        return Ok(false);
    }
    if pfd.revents & libc::POLLIN != 0 {
        return Ok(true);
    }
    if pfd.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0 {
        return Err(io::Error::new(io::ErrorKind::BrokenPipe, "tty hung up"));
    }
    Ok(false)
}

/// A serial tty, raw, non-blocking underneath, with timed reads.
#[derive(Debug)]
pub struct TtyPort {
    file: File,
    path: PathBuf,
    baud: u32,
    /// A USB adapter is behind the tty: its driver's output count says
    /// when the adapter took a write ([`Transport::unsent`]).
    usb: bool,
    /// A simulated adapter behind this pty counts what it took, standing
    /// in for that count ([`super::taken`]).
    simulated: Option<Arc<TakenCount>>,
}

pub use super::note::PortNote;

/// What to ask of a port besides raw mode and its baud.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PortSetup {
    /// Turn on the kernel's RS-485 direction control if the driver has it.
    pub rs485: bool,
    /// Take the port's lock first, and refuse a port another process holds
    /// ([`PortHeld`]) before touching it.
    pub exclusive: bool,
}

/// The port's lock is held by another open of it (a running jointd, or a
/// tool that locks its port): it was left as it was.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortHeld {
    pub path: PathBuf,
}

impl std::fmt::Display for PortHeld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} is held by another process (a running jointd, or another program \
             that locked it); it was left untouched",
            self.path.display()
        )
    }
}

impl std::error::Error for PortHeld {}

/// True when `e` says the port was held by another process ([`PortHeld`]).
pub fn is_held(e: &io::Error) -> bool {
    e.get_ref()
        .is_some_and(|inner| inner.downcast_ref::<PortHeld>().is_some())
}

/// Takes the advisory lock of the open tty `file`, without waiting. Held
/// until every descriptor of this open is closed.
fn lock_exclusive(file: &File, path: &Path) -> io::Result<()> {
    // SAFETY: flock on a valid, open descriptor; no pointers involved.
    let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if rc == 0 {
        return Ok(());
    }
    let e = io::Error::last_os_error();
    if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
        let held = PortHeld {
            path: path.to_path_buf(),
        };
        return Err(io::Error::other(held));
    }
    Err(e)
}

impl TtyPort {
    /// Opens `path` (any tty, a pty slave or a `/dev/serial/by-id` link
    /// included) raw at `baud`, leaving its RS-485 settings alone.
    pub fn open(path: &Path, baud: u32) -> io::Result<(TtyPort, Vec<PortNote>)> {
        Self::open_with(path, baud, PortSetup::default())
    }

    /// [`TtyPort::open`] with `setup`; what the port refuses becomes a note.
    pub fn open_with(
        path: &Path,
        baud: u32,
        setup: PortSetup,
    ) -> io::Result<(TtyPort, Vec<PortNote>)> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK)
            .open(path)?;
        if setup.exclusive {
            lock_exclusive(&file, path)?;
        }
        make_raw(file.as_fd(), baud)?;
        let mut notes = Vec::new();
        if let Err(e) = set_low_latency(&file) {
            notes.push(PortNote::IoctlUnsupported {
                what: "ASYNC_LOW_LATENCY",
                error: e.to_string(),
            });
        }
        if setup.rs485 {
            notes.extend(super::rs485::enable(&file));
        }
        // After ASYNC_LOW_LATENCY: the Linux FTDI driver turns it into a 1 ms
        // timer, and what is reported must be what is in effect.
        let adapter = super::adapter::detect(path);
        // A driver whose count cannot be read at all has none to confirm
        // writes with.
        let usb = adapter.usb && output_queued(file.as_fd()).is_ok();
        notes.push(PortNote::Adapter(adapter));
        Ok((
            TtyPort {
                file,
                path: path.to_path_buf(),
                baud,
                usb,
                simulated: None,
            },
            notes,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Behind a simulated adapter on a pty: its count of the bytes it took
    /// is read in place of a USB-serial driver's output count (a pty's own
    /// says 0 at once).
    pub fn counted_by(mut self, count: Arc<TakenCount>) -> Self {
        self.simulated = Some(count);
        self
    }
}

/// An opener for a tty path (USB adapter, pty, `/dev/serial/by-id` link);
/// `rs485`: ask for the kernel's RS-485 direction control. The port is
/// opened exclusive: a bus never shares its port with another process.
pub fn tty_opener(path: PathBuf, rs485: bool) -> Opener {
    Box::new(move |baud| {
        let setup = PortSetup {
            rs485,
            exclusive: true,
        };
        let (port, notes) = TtyPort::open_with(&path, baud, setup)?;
        Ok((Box::new(port) as Box<dyn Transport>, notes))
    })
}

/// Linux `struct serial_struct` prefix up to `flags`, for TIOCGSERIAL/TIOCSSERIAL.
#[repr(C)]
#[derive(Default)]
struct SerialStruct {
    kind: libc::c_int,
    line: libc::c_int,
    port: libc::c_uint,
    irq: libc::c_int,
    flags: libc::c_int,
    rest: [u32; 32],
}

const ASYNC_LOW_LATENCY: libc::c_int = 1 << 13;

fn set_low_latency(file: &File) -> io::Result<()> {
    let mut ss = SerialStruct::default();
    let fd = file.as_raw_fd();
    // SAFETY: TIOCGSERIAL writes a serial_struct; ours is larger than the kernel's.
    if unsafe { libc::ioctl(fd, libc::TIOCGSERIAL, &mut ss) } < 0 {
        return Err(io::Error::last_os_error());
    }
    ss.flags |= ASYNC_LOW_LATENCY;
    // SAFETY: same struct back.
    if unsafe { libc::ioctl(fd, libc::TIOCSSERIAL, &ss) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// The tty's output queue (`TIOCOUTQ`) as the driver reports it.
fn output_queued(fd: BorrowedFd<'_>) -> io::Result<libc::c_int> {
    let mut n: libc::c_int = 0;
    // SAFETY: TIOCOUTQ writes one int through a valid pointer.
    let rc = unsafe { libc::ioctl(fd.as_raw_fd(), libc::TIOCOUTQ, &mut n) };
    if rc < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(n)
}

/// The bytes not taken yet, from the driver's count `queued`. A count that
/// cannot be read, or is negative, says nothing was taken, never that all
/// was: the wait for it is bounded, and given up on it is evidence
/// against the pipeline ([`crate::bus::usb::confirm`]), where reading it as
/// 0 would hold the wire as if the write had left on time.
fn untaken(queued: io::Result<libc::c_int>) -> usize {
    queued.map_or(usize::MAX, |n| usize::try_from(n).unwrap_or(usize::MAX))
}

impl Transport for TtyPort {
    fn unsent(&mut self) -> Option<usize> {
        if self.usb {
            return Some(untaken(output_queued(self.file.as_fd())));
        }
        let count = self.simulated.as_ref()?;
        Some(count.unsent(std::time::Instant::now()))
    }

    fn write_all(&mut self, mut bytes: &[u8]) -> io::Result<()> {
        while !bytes.is_empty() {
            match self.file.write(bytes) {
                Ok(0) => {
                    return Err(io::Error::new(
                        io::ErrorKind::BrokenPipe,
                        "tty accepted no bytes",
                    ))
                }
                Ok(n) => {
                    // Only what the tty took is on its way: bytes a failed
                    // write (an unplugged simulator) never passed on would
                    // keep the count up for good. The simulator may report
                    // them taken first; the count reads 0 either way, and
                    // only this thread reads it.
                    if let Some(count) = &self.simulated {
                        count.wrote(n);
                    }
                    bytes = &bytes[n..];
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => wait_writable(&self.file)?,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        if !wait_readable(self.file.as_fd(), timeout)? {
            return Ok(0);
        }
        match self.file.read(buf) {
            Ok(0) => Err(io::Error::new(io::ErrorKind::UnexpectedEof, "tty closed")),
            Ok(n) => Ok(n),
            Err(e)
                if e.kind() == io::ErrorKind::WouldBlock
                    || e.kind() == io::ErrorKind::Interrupted =>
            {
                Ok(0)
            }
            Err(e) => Err(e),
        }
    }

    fn set_baud(&mut self, baud: u32) -> io::Result<()> {
        make_raw(self.file.as_fd(), baud)?;
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> u32 {
        self.baud
    }

    fn discard_input(&mut self) -> io::Result<()> {
        termios::tcflush(self.file.as_fd(), FlushArg::TCIFLUSH)?;
        Ok(())
    }
}

fn wait_writable(file: &File) -> io::Result<()> {
    let mut pfd = libc::pollfd {
        fd: file.as_raw_fd(),
        events: libc::POLLOUT,
        revents: 0,
    };
    // SAFETY: one valid pollfd.
    let n = unsafe { libc::poll(&mut pfd, 1, 100) };
    if n < 0 {
        return Err(io::Error::last_os_error());
    }
    if pfd.revents & (libc::POLLHUP | libc::POLLERR) != 0 {
        return Err(io::Error::new(io::ErrorKind::BrokenPipe, "tty hung up"));
    }
    Ok(())
}

#[cfg(test)]
#[path = "tty_tests.rs"]
mod tests;
