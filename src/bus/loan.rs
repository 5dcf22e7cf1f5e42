//! The port lent to a one-shot job on the owner's thread: what a check of
//! a configured bus (the doctor through REST) gets to work with. The owner
//! lends it only with every joint disabled, between its own frames, and
//! takes it back as it was (baud, an empty input, the line model listening
//! again); the job never sees the owner's state.

use std::fmt;
use std::path::PathBuf;

use crate::transport::adapter::AdapterInfo;
use crate::transport::Transport;

/// What the job is told of the bus it borrows.
pub struct PortLoan {
    pub bus: String,
    pub path: PathBuf,
    /// The baud the bus runs at (the port is at it when lent).
    pub baud: u32,
    /// The adapter the bus plans for, and how it was found.
    pub adapter: AdapterInfo,
    /// What opening the port reported (RS-485 direction, ioctls a pty lacks).
    pub notes: Vec<String>,
    /// The ids the bus knows.
    pub ids: Vec<u8>,
    /// How long past its modelled time the bus waits for a reply
    /// (`timing.reply_margin_us`).
    pub reply_margin: std::time::Duration,
    /// True once an e-stop is asked on the bus or the bus is stopping:
    /// the job stops before its next frame and gives the port back, and
    /// the owner runs the e-stop or its shutdown.
    pub stop_asked: Box<dyn Fn() -> bool + Send + Sync>,
}

impl fmt::Debug for PortLoan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PortLoan")
            .field("bus", &self.bus)
            .field("path", &self.path)
            .field("baud", &self.baud)
            .field("adapter", &self.adapter)
            .field("ids", &self.ids)
            .finish_non_exhaustive()
    }
}

/// What a job does with the lent port.
type Work = Box<dyn FnOnce(&mut dyn Transport, &PortLoan) + Send>;

/// A job run on the lent port; it answers its caller itself.
pub struct PortJob(Work);

impl PortJob {
    pub(crate) fn new(job: impl FnOnce(&mut dyn Transport, &PortLoan) + Send + 'static) -> Self {
        Self(Box::new(job))
    }

    pub(crate) fn run(self, port: &mut dyn Transport, loan: &PortLoan) {
        (self.0)(port, loan);
    }
}

impl fmt::Debug for PortJob {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("PortJob")
    }
}
