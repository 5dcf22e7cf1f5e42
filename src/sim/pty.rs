//! The simulator's end of a pseudo-terminal: the host opens the slave like a
//! USB adapter, through a stable symlink (`…/ttySIM0`) that survives an
//! unplug/replug cycle (replug makes a new pty and re-points the link).
//!
//! The simulator keeps its own slave descriptor open so the master never
//! sees a hang-up while the host closes and reopens its port; the host's
//! baud is read from the master (Linux routes a master's termios ioctls to
//! its slave).

use std::fs::{self, File};
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::Duration;

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;

use crate::transport::taken::{self, TakenCount};
use crate::transport::tty::{make_raw, read_baud, wait_readable};

use super::line::Line;

/// Name of the stable link inside the simulator's directory.
const LINK_NAME: &str = "ttySIM0";
/// Tells apart several simulators of one process.
static INSTANCE: AtomicU32 = AtomicU32::new(0);

struct Pty {
    master: File,
    /// Held so the master does not hang up while no host has the slave open.
    _slave: OwnedFd,
}

pub(crate) struct PtyLine {
    pty: Option<Pty>,
    dir: PathBuf,
    link: PathBuf,
    baud: u32,
    /// Behind an adapter model: what a USB-serial driver's output count
    /// would say, handed to a host in this process that opens the link
    /// (a pty's own count says 0 at once).
    taken: Option<Arc<TakenCount>>,
}

impl PtyLine {
    /// Opens a pty, raw at `baud`, linked from a fresh temp directory.
    pub(crate) fn open(baud: u32) -> io::Result<PtyLine> {
        let n = INSTANCE.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("jointd-sim-{}-{n}", std::process::id()));
        fs::create_dir_all(&dir)?;
        let link = dir.join(LINK_NAME);
        let mut line = PtyLine {
            pty: None,
            dir,
            link,
            baud,
            taken: None,
        };
        line.replug()?;
        Ok(line)
    }

    fn open_pty(&self) -> io::Result<(Pty, PathBuf)> {
        let p = openpty(None, None).map_err(io::Error::from)?;
        make_raw(p.slave.as_fd(), self.baud)?;
        let flags = fcntl(p.master.as_raw_fd(), FcntlArg::F_GETFL).map_err(io::Error::from)?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(p.master.as_raw_fd(), FcntlArg::F_SETFL(flags)).map_err(io::Error::from)?;
        let slave_path = fs::read_link(format!("/proc/self/fd/{}", p.slave.as_raw_fd()))?;
        let pty = Pty {
            master: File::from(p.master),
            _slave: p.slave,
        };
        Ok((pty, slave_path))
    }

    /// Points the stable link at `target` atomically (a rename over it).
    fn point_link(&self, target: &Path) -> io::Result<()> {
        let tmp = self.dir.join(format!("{LINK_NAME}.new"));
        let _ = fs::remove_file(&tmp);
        std::os::unix::fs::symlink(target, &tmp)?;
        fs::rename(&tmp, &self.link)
    }
}

impl Line for PtyLine {
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let Some(pty) = self.pty.as_mut() else {
            return Ok(0);
        };
        if !wait_readable(pty.master.as_fd(), timeout)? {
            return Ok(0);
        }
        match pty.master.read(buf) {
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(e),
        }
    }

    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let Some(pty) = self.pty.as_mut() else {
            return Ok(0);
        };
        match pty.master.write(bytes) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(0),
            Err(e) => Err(e),
        }
    }

    fn host_baud(&self) -> Option<u32> {
        let pty = self.pty.as_ref()?;
        read_baud(pty.master.as_fd()).ok().flatten()
    }

    /// Closes the pty (the host's descriptor hangs up) and removes the link,
    /// as the device node of an unplugged adapter disappears.
    fn unplug(&mut self) -> io::Result<()> {
        self.pty = None;
        if let Some(count) = &self.taken {
            count.settle();
        }
        match fs::remove_file(&self.link) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    fn replug(&mut self) -> io::Result<()> {
        if self.pty.is_some() {
            return Ok(());
        }
        let (pty, slave_path) = self.open_pty()?;
        self.point_link(&slave_path)?;
        self.pty = Some(pty);
        Ok(())
    }

    fn is_unplugged(&self) -> bool {
        self.pty.is_none()
    }

    /// A pty passes writes on whenever its reader gets them: that lag
    /// stands for the host's path to the adapter, so the count follows the
    /// model's reading ([`Line::took`]), not `_rule`.
    fn reports_taken(&mut self, _rule: Arc<dyn taken::TakeRule>) {
        self.taken.get_or_insert_with(Default::default);
    }

    fn taken_count(&self) -> Option<Arc<TakenCount>> {
        self.taken.clone()
    }

    fn took(&mut self, at: std::time::Instant, bytes: usize) {
        if let Some(count) = &self.taken {
            count.took(at, bytes);
        }
    }

    fn path(&self) -> Option<&Path> {
        Some(&self.link)
    }
}

impl Drop for PtyLine {
    fn drop(&mut self) {
        self.pty = None;
        let _ = fs::remove_file(&self.link);
        let _ = fs::remove_dir(&self.dir);
    }
}
