//! Why a simulator could not be built or run: one type for every part of
//! the simulator (its own module, so config, parameters and firmware
//! profiles all use it without importing each other).

use std::path::PathBuf;

use thiserror::Error;

/// Why a simulator could not be built or run.
#[derive(Debug, Error)]
pub enum SimError {
    #[error("bad device ids: {0}")]
    BadIds(String),
    #[error("baud {0} is not one the modules speak (500000, 230400, 115200, 38400, 19200)")]
    BadBaud(u32),
    #[error("bad firmware: {0}")]
    BadFirmware(String),
    #[error("bad adapter: {0}")]
    BadAdapter(String),
    #[error("bad write delay: {0}")]
    BadWriteDelay(String),
    #[error("bad hard stop: {0}")]
    BadHardStop(String),
    #[error("bad object: {0}")]
    BadObject(String),
    #[error("state file {path}: {why}")]
    StateFile { path: PathBuf, why: String },
    #[error("pseudo-terminal: {0}")]
    Pty(#[source] std::io::Error),
    #[error("simulator thread: {0}")]
    Thread(#[source] std::io::Error),
}
