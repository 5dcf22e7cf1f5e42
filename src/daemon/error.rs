//! What can keep the daemon from starting, each with the way out.

use std::net::SocketAddr;
use std::path::PathBuf;

use thiserror::Error;

use crate::bus::BusError;
use crate::control::limits::LimitError;
use crate::sim::SimError;

#[derive(Debug, Error)]
pub enum DaemonError {
    #[error("config file {path}: {why}")]
    Config { path: PathBuf, why: String },
    #[error(
        "refusing to listen on {addr} without a token: set --token (or JOINTD_TOKEN), \
         listen on 127.0.0.1, or pass --insecure"
    )]
    Insecure { addr: SocketAddr },
    #[error("token ({from}): {why}")]
    Token { from: String, why: String },
    #[error("{0}")]
    Policy(String),
    #[error("soft limits: {0}")]
    Limits(#[from] LimitError),
    #[error("bus: {0}")]
    Bus(#[from] BusError),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("no bus configured: give --bus PATH@BAUD, --sim N or [[bus]] in --config")]
    NoBus,
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
    #[error("{0}")]
    Foxglove(#[from] crate::foxglove::LiveError),
}

/// A failed bind, with the way out when the address is taken.
pub(super) fn listen_error(addr: SocketAddr, source: std::io::Error) -> DaemonError {
    let what = if source.kind() == std::io::ErrorKind::AddrInUse {
        format!(
            "cannot listen on {addr} (is another jointd running?); choose another address \
             with --listen, e.g. --listen 127.0.0.1:8081 (or `listen` in the config file)"
        )
    } else {
        format!("cannot listen on {addr}; choose another address with --listen")
    };
    DaemonError::Io { what, source }
}
