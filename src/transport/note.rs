//! What opening a port found worth telling the user. Its own file because
//! both the tty and its RS-485 setup produce notes, and the tty calls the
//! RS-485 setup: a note type in either would tie the two in a circle.

/// Something worth telling the user about a freshly opened port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortNote {
    /// `ASYNC_LOW_LATENCY` or RS-485 mode could not be set (normal on a pty).
    IoctlUnsupported { what: &'static str, error: String },
    /// RS-485 direction control: what the driver was left doing.
    Rs485(String),
    /// The USB adapter behind the tty (or none), found from sysfs after
    /// the port was set up, so its latency timer is the one in effect.
    Adapter(super::adapter::AdapterInfo),
}
