//! The device end of the line, as the runner thread needs it: timed reads,
//! non-blocking writes, the host port's baud, and unplug/replug. Two kinds:
//! the in-memory pipe here, the pseudo-terminal in [`super::pty`].

use std::io;
use std::path::Path;
use std::time::Duration;

use crate::transport::memory::MemoryPort;
use crate::transport::taken::{TakeRule, TakenCount};
use crate::transport::{is_hangup, Transport};

/// What the runner needs from the device end of a line.
pub(crate) trait Line: Send {
    /// Waits up to `timeout` for host bytes; `Ok(0)` on timeout or while unplugged.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Hands bytes to the host without blocking; returns how many it took.
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize>;
    /// The baud the host's port is set to now (unknown rates: `None`).
    fn host_baud(&self) -> Option<u32>;
    fn unplug(&mut self) -> io::Result<()>;
    fn replug(&mut self) -> io::Result<()>;
    fn is_unplugged(&self) -> bool;
    /// The path a host opens, for a tty-like line.
    fn path(&self) -> Option<&Path> {
        None
    }
    /// When bytes held on their way to the host (an adapter model) are due
    /// there; a plain line holds nothing.
    fn next_release(&self) -> Option<std::time::Instant> {
        None
    }
    /// Hands the host what is due by `now` (an adapter model).
    fn flush_due(&mut self, _now: std::time::Instant) -> io::Result<()> {
        Ok(())
    }
    /// When the bytes of the last read entered the wire, if the line knows
    /// better than the moment they were read (an adapter releases them at a
    /// USB frame boundary, whenever the runner gets to them).
    fn take_read_at(&mut self) -> Option<std::time::Instant> {
        None
    }
    /// Reads whose bytes had waited while the runner was not watching the
    /// line (dated to the earliest instant they may have been written)
    /// since the last call.
    fn take_undated_reads(&mut self) -> u64 {
        0
    }
    /// Host writes a write delay made miss the USB frame they would have
    /// made, since the last call (an adapter model).
    fn take_slipped_writes(&mut self) -> u64 {
        0
    }
    /// When the host wrote the first byte of the last read, if the line
    /// knows (an in-memory pipe does; a pty's kernel may pass bytes on late).
    fn take_written_at(&mut self) -> Option<std::time::Instant> {
        None
    }
    /// An adapter model in front will report when it takes the host's
    /// bytes ([`Self::took`]): a line that can pass that on to the host
    /// does (an in-memory pipe, as a USB-serial driver's output count; a
    /// pty cannot). A line that knows each host write's instant runs the
    /// model's `rule` at the write instead ([`Self::taken_at`]).
    fn reports_taken(&mut self, _rule: std::sync::Arc<dyn TakeRule>) {}
    /// What a host opening this line by path reads in place of a
    /// USB-serial driver's output count, once an adapter model reports
    /// ([`Self::reports_taken`]; a pty's own count says 0 at once).
    fn taken_count(&self) -> Option<std::sync::Arc<TakenCount>> {
        None
    }
    /// The adapter model takes `bytes` of the host's at `at`, the USB frame
    /// they leave in.
    fn took(&mut self, _at: std::time::Instant, _bytes: usize) {}
    /// The frame the model's rule named, at the host's write, for the
    /// first of the `bytes` just read (`None`: the model decides now, and
    /// reports it with [`Self::took`]).
    fn taken_at(&mut self, _bytes: usize) -> Option<std::time::Instant> {
        None
    }
}

/// The device end of an in-memory pipe.
pub(crate) struct MemoryLine {
    port: MemoryPort,
}

impl MemoryLine {
    pub(crate) fn new(port: MemoryPort) -> Self {
        Self { port }
    }
}

impl Line for MemoryLine {
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        match self.port.read_timeout(buf, timeout) {
            Err(e) if is_hangup(&e) => Ok(0),
            other => other,
        }
    }

    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        self.port.write_all(bytes).map(|()| bytes.len())
    }

    fn take_written_at(&mut self) -> Option<std::time::Instant> {
        self.port.take_written_at()
    }

    /// The pipe knows when each write was made: the count follows the
    /// model from there, as a driver's does, however late the simulator's
    /// thread reads the bytes.
    fn reports_taken(&mut self, rule: std::sync::Arc<dyn TakeRule>) {
        self.port.take_by(rule);
    }

    fn taken_at(&mut self, bytes: usize) -> Option<std::time::Instant> {
        self.port.decided(bytes)
    }

    /// The pipe's count, for faults (a count that never falls).
    fn taken_count(&self) -> Option<std::sync::Arc<TakenCount>> {
        Some(self.port.taken_count())
    }

    fn took(&mut self, at: std::time::Instant, bytes: usize) {
        self.port.took(at, bytes);
    }

    /// A UART starts sending a host frame when it is written, not when the
    /// simulator's thread, waking from its wait, gets to read it.
    fn take_read_at(&mut self) -> Option<std::time::Instant> {
        self.port.take_written_at()
    }

    fn host_baud(&self) -> Option<u32> {
        Some(self.port.baud())
    }

    fn unplug(&mut self) -> io::Result<()> {
        self.port.set_hung_up(true);
        Ok(())
    }

    fn replug(&mut self) -> io::Result<()> {
        // Restoring clears the pipe: only do it if the line really was down.
        if self.port.is_hung_up() {
            self.port.set_hung_up(false);
        }
        Ok(())
    }

    fn is_unplugged(&self) -> bool {
        self.port.is_hung_up()
    }
}
