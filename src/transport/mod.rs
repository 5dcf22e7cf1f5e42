//! Byte transports the bus runs over: a serial tty (USB adapter or
//! pseudo-terminal) or an in-memory pipe for fast tests.
//!
//! The bus owner is a dedicated OS thread, so the interface is blocking with
//! precise timeouts (`poll(2)` on a tty, a condvar in memory): tokio's timer
//! has millisecond granularity, the wire needs tens of microseconds.
//!
//! # Layout
//! - [`Transport`]: what the bus owner needs from a line.
//! - [`memory`]: an in-memory duplex pipe with a shared "baud" and hang-up.
//! - [`tty`]: a tty opened raw at a baud rate (real adapter or pty slave).
//! - [`rs485`]: the kernel's RS-485 direction control on a tty, where it exists.
//! - [`note`]: what opening a port found worth telling ([`note::PortNote`]).
//! - [`adapter`]: the USB adapter in between: its timing model and its detection from sysfs.
//! - [`taken`]: a simulated adapter's stand-in for a USB-serial driver's output count.
//! - [`Opener`]: how a bus opens its port, and again after it was lost.

pub mod adapter;
pub mod memory;
pub(crate) mod note;
pub(crate) mod rs485;
pub mod taken;
pub mod tty;

use std::io;
use std::time::Duration;

pub use note::PortNote;

/// Opens a port at a baud, and again after it was lost: a tty by path for
/// a real bus ([`tty::tty_opener`]), a simulator's pty with its adapter's
/// count (`SimHandle::pty_opener`).
pub type Opener =
    Box<dyn FnMut(u32) -> io::Result<(Box<dyn Transport>, Vec<PortNote>)> + Send + 'static>;

/// A half-duplex serial line as the host sees it.
///
/// Errors of kind `BrokenPipe`/`UnexpectedEof` mean the line is gone (adapter
/// unplugged, pty hung up): the caller reopens; others are passing I/O faults.
pub trait Transport: Send {
    /// Hands all bytes to the line. Returns once the OS (or the pipe) took
    /// them, not when they left the wire: pacing is the caller's job.
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()>;

    /// Waits up to `timeout` for bytes. `Ok(0)` means the timeout passed with
    /// nothing to read; a hung-up line is an error, never `Ok(0)`.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;

    /// Changes the line speed. A pty has no wire, but records the setting, and
    /// the simulator reads it to decide whether host and device speak the same baud.
    fn set_baud(&mut self, baud: u32) -> io::Result<()>;

    /// The line speed last set.
    fn baud(&self) -> u32;

    /// Drops bytes received but not yet read (after a baud change or reopen).
    fn discard_input(&mut self) -> io::Result<()>;

    /// Bytes handed over that the adapter has not taken yet, where the
    /// line can tell: on a USB-serial tty `TIOCOUTQ` counts the driver's
    /// buffer and the USB transfer in flight, which ends when the adapter
    /// takes the bytes (at the USB frame they leave in). `None` where the
    /// line cannot tell (a pty says 0 at once, whenever its reader gets
    /// the bytes).
    fn unsent(&mut self) -> Option<usize> {
        None
    }
}

/// True for errors that mean the line is gone rather than a passing fault.
pub fn is_hangup(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::BrokenPipe | io::ErrorKind::UnexpectedEof | io::ErrorKind::NotConnected
    ) || e.raw_os_error() == Some(libc::EIO)
        || e.raw_os_error() == Some(libc::ENXIO)
        || e.raw_os_error() == Some(libc::ENODEV)
}
