//! The flags of `jointd [run]` and the shape of its config file.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::Deserialize;

use crate::bus::BusConfig;
use crate::control::limits::LimitRule;
use crate::control::teleop::WatchdogDefault;

/// Default HTTP address: loopback only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8080";
/// Name of the bus `--sim` starts.
pub const SIM_BUS_NAME: &str = "sim0";

/// Flags of the run command (also accepted with no subcommand at all).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RunArgs {
    /// A serial bus, `[NAME=]PATH@BAUD` (repeatable), e.g. `/dev/ttyUSB0@500000`
    /// or `left=/dev/serial/by-id/usb-FTDI…@230400`.
    #[arg(long = "bus", value_name = "[NAME=]PATH@BAUD")]
    pub buses: Vec<String>,
    /// Start an in-process simulated bus `sim0` of N joints (ids 1..=N) on a
    /// pseudo-terminal, opened through the same serial code as hardware.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=159))]
    pub sim: Option<u8>,
    /// Baud of the simulated bus.
    #[arg(long, value_name = "BAUD", default_value_t = 500_000)]
    pub sim_baud: u32,
    /// Firmware revision of the simulated joints: `2.0.1` (default), `2.0.8`,
    /// or per id, e.g. `1-8=2.0.8,9-16=2.0.1` (ids not named run 2.0.1).
    #[arg(long, value_name = "SPEC", requires = "sim")]
    pub sim_firmware: Option<String>,
    /// The USB adapter the simulated bus sits behind: `native` (default),
    /// `ftdi[:MS]`, `ch340`, `cp2102`, `ft232h[:MS]`; the bus plans for it
    /// (behind a USB model it runs over an in-memory line, not a pty).
    #[arg(long, value_name = "MODEL", requires = "sim")]
    pub sim_adapter: Option<String>,
    /// Host writes reach the simulated adapter late by a random delay with
    /// these quantiles, µs: `P50,P99,MAX` or `P50,P99,P99.9,MAX` (a busy
    /// host or USB hub). Needs `--sim-adapter`.
    #[arg(long, value_name = "P50,P99[,P99.9],MAX", requires = "sim_adapter")]
    pub sim_write_delay_us: Option<String>,
    /// A mechanical end stop of a simulated joint, `ID=DEG` (repeatable),
    /// e.g. `--sim-hard-stop 1=-40`: what homing finds.
    #[arg(long, value_name = "ID=DEG", requires = "sim")]
    pub sim_hard_stop: Vec<String>,
    /// An elastic object at a simulated joint, `ID=DEG:NM_PER_DEG`
    /// (repeatable), e.g. `--sim-object 2=30:0.05`: what a grasp closes on.
    #[arg(long, value_name = "ID=DEG:NM_PER_DEG", requires = "sim")]
    pub sim_object: Vec<String>,
    /// HTTP address to listen on [default: 127.0.0.1:8080]; port 0 picks a free
    /// port (the first line on stdout says which).
    #[arg(long, value_name = "ADDR", env = "JOINTD_LISTEN")]
    pub listen: Option<SocketAddr>,
    /// Bearer token required on everything but /healthz (and the dashboard's
    /// files). An empty or blank token is refused at start.
    #[arg(
        long,
        env = "JOINTD_TOKEN",
        hide_env_values = true,
        conflicts_with = "token_file"
    )]
    pub token: Option<String>,
    /// Read the token from this file (a container secret); trailing
    /// newlines are ignored, an empty file is refused.
    #[arg(long, value_name = "FILE", env = "JOINTD_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// Accept requests whose Host header is this name or IP (repeatable, or
    /// comma-separated in the environment); loopback names and the listen IP
    /// are always accepted, `*` accepts any host. Replaces `allowed_hosts`.
    #[arg(
        long = "allowed-host",
        value_name = "HOST",
        env = "JOINTD_ALLOWED_HOSTS",
        value_delimiter = ','
    )]
    pub allowed_hosts: Vec<String>,
    /// Let a browser page of this origin (`scheme://host[:port]`) change
    /// things and open the WebSocket (repeatable, or comma-separated in the
    /// environment). Replaces `allowed_origins`.
    #[arg(
        long = "allowed-origin",
        value_name = "ORIGIN",
        env = "JOINTD_ALLOWED_ORIGINS",
        value_delimiter = ','
    )]
    pub allowed_origins: Vec<String>,
    /// Largest request body, bytes [default: 1048576]; larger ones get 413.
    #[arg(long, value_name = "BYTES", env = "JOINTD_MAX_BODY_BYTES")]
    pub max_body_bytes: Option<usize>,
    /// Allow listening beyond loopback without a token.
    #[arg(long)]
    pub insecure: bool,
    /// TOML config file (see jointd.example.toml): `listen`, `token`,
    /// `token_file`, `insecure`, `allowed_hosts`, `allowed_origins`,
    /// `max_body_bytes`, `web_dir`, `state_dir`, `foxglove`, `[[bus]]`, `[[limit]]`,
    /// `[[joint]]`, `[[hand]]`, `[watchdog]`, `[ros2]`.
    /// Flags and environment variables override it.
    #[arg(long, value_name = "FILE", env = "JOINTD_CONFIG")]
    pub config: Option<PathBuf>,
    /// Serve the dashboard from this folder instead of the copy built into
    /// the binary (while editing web/).
    #[arg(long, value_name = "DIR")]
    pub web_dir: Option<PathBuf>,
    /// Where the state file (saved poses) lives; without one, poses last
    /// until the daemon stops.
    #[arg(long, value_name = "DIR", env = "JOINTD_STATE_DIR")]
    pub state_dir: Option<PathBuf>,
    /// Join ROS 2 over Zenoh (as `[ros2] enabled = true`): joint states,
    /// diagnostics and joint commands on rmw_zenoh's key expressions.
    #[arg(long)]
    pub ros2: bool,
    /// Zenoh endpoint to connect to (repeatable) [default: tcp/127.0.0.1:7447].
    #[arg(long, value_name = "ENDPOINT")]
    pub ros2_connect: Vec<String>,
    /// The ROS domain [default: ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID")]
    pub ros2_domain_id: Option<u32>,
    /// Serve the live view to the Foxglove app (ws://ADDR): a port, e.g.
    /// `8765`, listens on loopback; IP:PORT binds as given (Foxglove's
    /// protocol has no authentication: docs/foxglove.md); port 0 picks a
    /// free port (the log says which). The channels of a recording. Off by
    /// default.
    #[arg(long, value_name = "ADDR", value_parser = crate::foxglove::parse_addr)]
    pub foxglove: Option<SocketAddr>,
}

/// The config file. Flags override its values.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileConfig {
    pub listen: Option<SocketAddr>,
    pub token: Option<String>,
    pub token_file: Option<PathBuf>,
    #[serde(default)]
    pub insecure: bool,
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    #[serde(default)]
    pub allowed_origins: Vec<String>,
    pub max_body_bytes: Option<usize>,
    #[serde(default, rename = "bus")]
    pub buses: Vec<BusConfig>,
    #[serde(default, rename = "limit")]
    pub limits: Vec<LimitRule>,
    #[serde(default, rename = "joint")]
    pub joints: Vec<JointName>,
    #[serde(default)]
    pub watchdog: WatchdogDefault,
    pub web_dir: Option<PathBuf>,
    /// Where the state file (saved poses) lives.
    pub state_dir: Option<PathBuf>,
    /// `[[hand]]`: named sets of joints, possibly on several buses.
    #[serde(default, rename = "hand")]
    pub hands: Vec<crate::hands::HandConfig>,
    /// `[ros2]`: the ROS 2 bridge over Zenoh (off by default).
    #[serde(default)]
    pub ros2: crate::ros2::Ros2Config,
    /// `[[tokens]]`: tokens with a name and a scope (read, operate,
    /// admin), each secret from a file or the environment.
    #[serde(default)]
    pub tokens: Vec<super::tokens::TokenConfig>,
    /// `foxglove = "8765"` (loopback) or `"IP:PORT"`: the live Foxglove
    /// view (off when absent).
    pub foxglove: Option<String>,
}

/// `[[joint]]`: a name for a joint, shown in the API, telemetry and dashboard.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointName {
    /// Absent: the joint with this id on every bus.
    pub bus: Option<String>,
    pub id: u8,
    pub name: String,
}
