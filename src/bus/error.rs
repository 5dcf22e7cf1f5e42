//! Errors of a bus: "the device refused" is not "the bus failed".
//! The API maps each variant to one HTTP status (api/error.rs).

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum BusError {
    /// The device did not answer (504).
    #[error(
        "device {dev_id} did not answer {what} after {attempts} attempt(s) of {timeout_us} µs each"
    )]
    Timeout {
        dev_id: u8,
        what: String,
        attempts: u32,
        timeout_us: u64,
    },
    /// The port is lost and being retried (503).
    #[error("bus {bus} is down: {reason}")]
    Down { bus: String, reason: String },
    /// The device answered RES failure (409/502-ish: the device said no).
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
    /// No such device on this bus (404).
    #[error("device {dev_id} is not known on bus {bus}")]
    UnknownDevice { bus: String, dev_id: u8 },
    /// The device is not in a state that allows this (409), e.g. jog while disabled.
    #[error("{0}")]
    WrongState(String),
    /// A request the owner refuses as malformed (422).
    #[error("{0}")]
    Invalid(String),
    /// Too many requests waiting (503, retry).
    #[error("request queue full ({depth} waiting)")]
    Busy { depth: usize },
    /// An e-stop cancelled this request before it reached the wire.
    #[error("preempted by an emergency stop")]
    Preempted,
    /// The owner did not answer in time (should not happen; 503).
    #[error("bus owner did not answer in time")]
    OwnerTimeout,
    /// The owner thread has stopped (shutdown).
    #[error("bus owner stopped")]
    Stopped,
}
