//! Errors of a bus: what happened, told apart so callers can act on it —
//! "the device refused" is not "the device answered something else", and
//! neither is "the bus failed". Which HTTP status each becomes is the HTTP
//! layer's business (`http/error.rs`), not the bus's.

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum BusError {
    /// The device did not answer.
    #[error(
        "device {dev_id} did not answer {what} after {attempts} attempt(s) of {timeout_us} µs each"
    )]
    Timeout {
        dev_id: u8,
        what: String,
        attempts: u32,
        timeout_us: u64,
    },
    /// The port is lost and being retried.
    #[error("bus {bus} is down: {reason}")]
    Down { bus: String, reason: String },
    /// The device answered RES failure: it understood and said no.
    #[error("device {dev_id} refused {what} (RES code {code})")]
    Refused { dev_id: u8, what: String, code: u8 },
    /// A write's read-back shows another value.
    #[error("device {dev_id}: wrote {expected} to index {index}, read back {found}")]
    VerifyMismatch {
        dev_id: u8,
        index: u8,
        expected: u16,
        found: u16,
    },
    /// A write went out, but its confirmation (RES or read-back) never came
    /// after the retries its parameter allows: the device may or may not
    /// have taken it. Never "not written".
    #[error("device {dev_id}: {what} was sent but not confirmed ({reason}); it may or may not have taken effect")]
    Unverified {
        dev_id: u8,
        index: u8,
        value: u16,
        what: String,
        reason: String,
    },
    /// The device answered, but not what was asked (another block, not a
    /// RES): the device's failure, not the request's.
    #[error("{0}")]
    UnexpectedReply(String),
    /// No such device on this bus.
    #[error("device {dev_id} is not known on bus {bus}")]
    UnknownDevice { bus: String, dev_id: u8 },
    /// The device is not in a state that allows this, e.g. jog while disabled.
    #[error("{0}")]
    WrongState(String),
    /// A request the owner refuses as malformed (the caller's mistake).
    #[error("{0}")]
    Invalid(String),
    /// Too many requests waiting (retry later).
    #[error("request queue full ({depth} waiting)")]
    Busy { depth: usize },
    /// An e-stop cancelled this request: before it reached the wire, or
    /// while it waited for its reply (then whether a write took is unknown;
    /// the write paths report it unverified).
    #[error("preempted by an emergency stop")]
    Preempted,
    /// The owner did not answer in time (should not happen).
    #[error("bus owner did not answer in time")]
    OwnerTimeout,
    /// The owner thread has stopped (shutdown).
    #[error("bus owner stopped")]
    Stopped,
}
