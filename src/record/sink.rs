//! What the MCAP writer writes into: a stream that never fails towards the
//! writer, and keeps the first I/O error for [`super::mcap_file`] to report.
//!
//! Why: the `mcap` writer leaves itself without a stream when an I/O error
//! hits it while it opens or closes a chunk, and its next call (its own
//! `Drop` included) then panics. A full disk did exactly that. So the
//! writer is never shown an error: a failed write is kept here, every later
//! byte is dropped, and the file's owner asks [`Sink::failure`] after each
//! call and stops the recording with the error the disk gave.
//!
//! The writer runs with seeking off (chunks are built in memory and written
//! whole), so the only seek it makes is asking the position, which the sink
//! counts itself.

use std::io::{self, Seek, SeekFrom, Write};
use std::sync::{Arc, Mutex};

/// The first I/O error of a sink, readable while the writer holds the sink.
#[derive(Debug, Clone, Default)]
pub struct Failure(Arc<Mutex<Option<io::Error>>>);

impl Failure {
    /// The error kept, as a fresh `io::Error` of the same OS code or kind.
    pub fn get(&self) -> Option<io::Error> {
        let kept = self.0.lock().unwrap_or_else(|p| p.into_inner());
        kept.as_ref().map(|e| match e.raw_os_error() {
            Some(code) => io::Error::from_raw_os_error(code),
            None => io::Error::new(e.kind(), e.to_string()),
        })
    }

    fn set(&self, e: io::Error) {
        let mut kept = self.0.lock().unwrap_or_else(|p| p.into_inner());
        kept.get_or_insert(e);
    }

    fn is_set(&self) -> bool {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).is_some()
    }
}

/// A write-only stream over `W` that swallows its errors (see the module).
#[derive(Debug)]
pub struct Sink<W> {
    inner: W,
    /// Bytes handed in, written or not: the position the writer sees.
    pos: u64,
    failure: Failure,
}

impl<W: Write> Sink<W> {
    pub fn new(inner: W) -> (Self, Failure) {
        let failure = Failure::default();
        let sink = Self {
            inner,
            pos: 0,
            failure: failure.clone(),
        };
        (sink, failure)
    }

    /// Flushes what is buffered below; an error is kept like a write's.
    pub fn flush_inner(&mut self) {
        if !self.failure.is_set() {
            if let Err(e) = self.inner.flush() {
                self.failure.set(e);
            }
        }
    }

    pub fn get_ref(&self) -> &W {
        &self.inner
    }
}

impl<W: Write> Write for Sink<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if !self.failure.is_set() {
            if let Err(e) = self.inner.write_all(buf) {
                self.failure.set(e);
            }
        }
        self.pos += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        self.flush_inner();
        Ok(())
    }
}

/// The position only: the writer, seeking off, asks nothing else.
impl<W: Write> Seek for Sink<W> {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        match to {
            SeekFrom::Current(0) => Ok(self.pos),
            SeekFrom::Start(n) if n == self.pos => Ok(self.pos),
            _ => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "a recording's file is written front to back",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Takes `room` bytes, then fails like a full disk.
    pub(crate) struct Full {
        pub room: usize,
        pub taken: Vec<u8>,
    }

    impl Write for Full {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.taken.len() + buf.len() > self.room {
                return Err(io::Error::from_raw_os_error(libc::ENOSPC));
            }
            self.taken.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn the_first_error_is_kept_and_later_bytes_are_counted_not_written() {
        let (mut sink, failure) = Sink::new(Full {
            room: 4,
            taken: Vec::new(),
        });
        assert!(sink.write_all(b"abc").is_ok());
        assert!(failure.get().is_none());
        assert!(sink.write_all(b"defg").is_ok(), "the writer never sees it");
        assert!(sink.write_all(b"h").is_ok());
        assert_eq!(sink.stream_position().unwrap(), 8);
        assert_eq!(sink.get_ref().taken, b"abc", "nothing after the failure");
        let e = failure.get().unwrap();
        assert_eq!(e.raw_os_error(), Some(libc::ENOSPC));
        assert!(sink.seek(SeekFrom::Start(0)).is_err());
    }
}
