//! `jointd [run]`: config file and flags → buses (serial or an in-process
//! simulator: on a pty, or behind a USB adapter model on an in-memory line)
//! → the HTTP API → on SIGINT/SIGTERM stop accepting, let the requests under
//! way finish (for a bounded time), disable every joint, close the ports,
//! close the recordings, exit 0.

use std::collections::BTreeMap;
use std::future::IntoFuture;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use thiserror::Error;
use tokio::net::TcpListener;

use crate::config_locate::{key_in_table_array, table_array_line};
use tokio::signal::unix::{signal, SignalKind};

use crate::bus::{
    spawn_bus, spawn_bus_on, spawn_bus_with, AdapterSetting, BusConfig, BusError, BusHandle,
};
use crate::control::limits::{LimitError, LimitRule, SoftLimits};
use crate::control::teleop::{WatchdogDefault, MAX_HOLD, MIN_HOLD};
use crate::control::Control;
use crate::http::policy::{RequestPolicy, DEFAULT_MAX_BODY_BYTES};
use crate::http::state::HttpOptions;
use crate::http::{app, AppState};
use crate::protocol::is_device_id;
use crate::sim::{AdapterModel, Firmware, SimConfig, SimError, SimHandle, Simulator};
use crate::transport::{Opener, Transport};

/// Default HTTP address: loopback only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8080";
/// Name of the bus `--sim` starts.
pub const SIM_BUS_NAME: &str = "sim0";
/// Reply slack of the `--sim` bus, µs (see [`crate::bus::Timing`]).
const SIM_REPLY_MARGIN_US: u64 = 20_000;
/// How long shutdown waits for each bus to disable its joints and close.
const BUS_STOP_TIMEOUT: Duration = Duration::from_secs(5);

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
    /// `max_body_bytes`, `web_dir`, `state_dir`, `[[bus]]`, `[[limit]]`, `[[joint]]`,
    /// `[[hand]]`, `[watchdog]`, `[ros2]`.
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
}

/// Everything the daemon will run with, after file and flags are merged.
#[derive(Debug)]
pub struct Plan {
    pub listen: SocketAddr,
    pub token: Option<String>,
    pub buses: Vec<BusConfig>,
    pub limits: SoftLimits,
    /// The simulated bus of `--sim`, checked.
    pub sim: Option<SimConfig>,
    /// The core's options (`managed` is filled in when the buses start).
    pub control: crate::control::Options,
    /// What HTTP alone reads of the config.
    pub http: HttpOptions,
    /// The ROS 2 bridge, when enabled.
    pub ros2: Option<crate::ros2::Ros2Config>,
}

fn load_file(path: &PathBuf) -> Result<FileConfig, DaemonError> {
    let bad = |why: String| DaemonError::Config {
        path: path.clone(),
        why,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let file: FileConfig = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
    // The parser placed type errors; values it accepted but a bus cannot run
    // with are placed here, so the user is told the line, not just the key.
    for (i, bus) in file.buses.iter().enumerate() {
        if let Some((key, why)) = bus.invalid_field() {
            let at = match key_in_table_array(&text, "bus", i, key) {
                Some((line, column)) => format!("line {line}, column {column}: "),
                None => String::new(),
            };
            return Err(bad(format!(
                "{at}`{key}` of [[bus]] `{}` (bus #{}): {why}",
                bus.name,
                i + 1
            )));
        }
    }
    if let Err(LimitError::Bad { rule, why }) = SoftLimits::new(file.limits.clone()) {
        let at = table_array_line(&text, "limit", rule.saturating_sub(1))
            .map_or_else(String::new, |line| format!("line {line}: "));
        return Err(bad(format!("{at}[[limit]] #{rule}: {why}")));
    }
    Ok(file)
}

/// A failed bind, with the way out when the address is taken.
fn listen_error(addr: SocketAddr, source: std::io::Error) -> DaemonError {
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

/// Merges the config file and the flags, and refuses unsafe combinations.
pub fn plan(args: &RunArgs) -> Result<Plan, DaemonError> {
    let file = match &args.config {
        Some(path) => load_file(path)?,
        None => FileConfig::default(),
    };
    let default_listen: SocketAddr = DEFAULT_LISTEN.parse().map_err(|_| DaemonError::NoBus)?;
    let listen = args.listen.or(file.listen).unwrap_or(default_listen);
    let token = token(args, &file)?;
    let policy = request_policy(listen, args, &file)?;
    if !listen.ip().is_loopback() && token.is_none() && !(args.insecure || file.insecure) {
        return Err(DaemonError::Insecure { addr: listen });
    }
    let mut buses = file.buses;
    for spec in &args.buses {
        buses.push(BusConfig::parse_cli(spec)?);
    }
    let sim = args.sim.map(|n| sim_config(n, args)).transpose()?;
    if buses.is_empty() && sim.is_none() {
        return Err(DaemonError::NoBus);
    }
    let bus_names: Vec<String> = buses
        .iter()
        .map(|b| b.name.clone())
        .chain(sim.as_ref().map(|_| SIM_BUS_NAME.to_string()))
        .collect();
    let hands = crate::hands::resolve(&file.hands, &bus_names)
        .map_err(|e| DaemonError::Policy(format!("[[hand]]: {e}")))?;
    let state_dir = args.state_dir.clone().or(file.state_dir);
    let poses = crate::hands::StateStore::open(hands, state_dir.as_deref())
        .map_err(|e| DaemonError::Policy(e.to_string()))?;
    match poses.state_path() {
        Some(path) => {
            tracing::info!(state_file = %path.display(), "poses are kept in the state file")
        }
        None if !poses.hands().is_empty() => tracing::warn!(
            "no state_dir: saved poses last until the daemon stops (set state_dir or --state-dir)"
        ),
        None => {}
    }
    let hand_names: Vec<String> = poses.hands().iter().map(|h| h.name.clone()).collect();
    let ros2 = ros2_config(file.ros2, args, &bus_names, &hand_names)?;
    let control = crate::control::Options {
        ros2: ros2
            .as_ref()
            .map(|_| std::sync::Arc::new(crate::control::ros2_stats::Ros2Stats::default())),
        hands: Some(std::sync::Arc::new(poses)),
        joint_names: joint_names(&file.joints, args)?,
        watchdog: checked_watchdog(file.watchdog, args)?,
        recordings_dir: state_dir.as_ref().map(|d| d.join("recordings")),
        // Filled in when the buses start (the simulator's bus is added then).
        managed: Default::default(),
    };
    let http = HttpOptions {
        web_dir: args.web_dir.clone().or(file.web_dir),
        policy,
    };
    Ok(Plan {
        listen,
        token,
        buses,
        limits: SoftLimits::new(file.limits)?,
        sim,
        control,
        http,
        ros2,
    })
}

/// `[ros2]` with the flags over it; `None` when the bridge is off.
fn ros2_config(
    mut cfg: crate::ros2::Ros2Config,
    args: &RunArgs,
    buses: &[String],
    hands: &[String],
) -> Result<Option<crate::ros2::Ros2Config>, DaemonError> {
    cfg.enabled |= args.ros2;
    if !args.ros2_connect.is_empty() {
        cfg.connect = args.ros2_connect.clone();
    }
    cfg.domain_id = args.ros2_domain_id.or(cfg.domain_id);
    if !cfg.enabled {
        return Ok(None);
    }
    if !crate::ros2::BUILT {
        return Err(DaemonError::Policy(
            crate::ros2::Ros2Error::NotBuilt.to_string(),
        ));
    }
    cfg.checked(buses, hands)
        .map(Some)
        .map_err(|e| DaemonError::Policy(e.to_string()))
}

/// The token of the flags (or their environment variables), else of the
/// file; given twice at one level, empty or unusable: refused.
fn token(args: &RunArgs, file: &FileConfig) -> Result<Option<String>, DaemonError> {
    if args.token.is_some() || args.token_file.is_some() {
        return token_from(
            args.token.as_deref(),
            args.token_file.as_ref(),
            "--token or JOINTD_TOKEN",
        );
    }
    if file.token.is_some() && file.token_file.is_some() {
        return Err(config_error(
            args,
            "give `token` or `token_file`, not both".into(),
        ));
    }
    token_from(
        file.token.as_deref(),
        file.token_file.as_ref(),
        "`token` in the config file",
    )
}

fn token_from(
    value: Option<&str>,
    path: Option<&PathBuf>,
    what: &str,
) -> Result<Option<String>, DaemonError> {
    let (text, from) = match (value, path) {
        (Some(v), _) => (v.to_owned(), what.to_owned()),
        (None, Some(p)) => {
            let from = format!("file {}", p.display());
            let text = std::fs::read_to_string(p).map_err(|e| DaemonError::Token {
                from: from.clone(),
                why: format!("cannot read it: {e}"),
            })?;
            (text.trim_end_matches(['\n', '\r']).to_owned(), from)
        }
        (None, None) => return Ok(None),
    };
    match token_problem(&text) {
        Some(why) => Err(DaemonError::Token {
            from,
            why: why.into(),
        }),
        None => Ok(Some(text)),
    }
}

/// Why a token cannot be used: an `Authorization` header cannot carry
/// blanks at its ends or control characters, and an empty token would
/// silently turn auth off.
fn token_problem(token: &str) -> Option<&'static str> {
    if token.is_empty() {
        Some("it is empty; give a token, or leave the option out to run without one")
    } else if token.trim().is_empty() {
        Some("it is only whitespace")
    } else if token.trim() != token {
        Some("it starts or ends with whitespace, which an Authorization header cannot carry")
    } else if token.chars().any(char::is_control) {
        Some("it contains a control character")
    } else {
        None
    }
}

/// `allowed_hosts`, `allowed_origins`, `max_body_bytes`: flags replace the file's.
fn request_policy(
    listen: SocketAddr,
    args: &RunArgs,
    file: &FileConfig,
) -> Result<RequestPolicy, DaemonError> {
    let pick = |flag: &Vec<String>, key: &Vec<String>| {
        if flag.is_empty() {
            key.clone()
        } else {
            flag.clone()
        }
    };
    let hosts = pick(&args.allowed_hosts, &file.allowed_hosts);
    let origins = pick(&args.allowed_origins, &file.allowed_origins);
    let max_body = args
        .max_body_bytes
        .or(file.max_body_bytes)
        .unwrap_or(DEFAULT_MAX_BODY_BYTES);
    RequestPolicy::new(Some(listen), &hosts, &origins, max_body).map_err(DaemonError::Policy)
}

fn config_error(args: &RunArgs, why: String) -> DaemonError {
    DaemonError::Config {
        path: args.config.clone().unwrap_or_default(),
        why,
    }
}

/// `[[joint]]` entries as a lookup; ids in range, one name per joint.
fn joint_names(
    joints: &[JointName],
    args: &RunArgs,
) -> Result<BTreeMap<(Option<String>, u8), String>, DaemonError> {
    let mut names = BTreeMap::new();
    for (i, j) in joints.iter().enumerate() {
        let at = format!("joint[{i}]");
        if !is_device_id(j.id) {
            return Err(config_error(
                args,
                format!("{at}.id = {}: device ids are 1..=159", j.id),
            ));
        }
        if j.name.trim().is_empty() {
            return Err(config_error(args, format!("{at}.name is empty")));
        }
        if names
            .insert((j.bus.clone(), j.id), j.name.clone())
            .is_some()
        {
            return Err(config_error(
                args,
                format!("{at}: joint {} is named twice", j.id),
            ));
        }
    }
    Ok(names)
}

/// `[watchdog]`: 0 (off) or within what a client may declare.
fn checked_watchdog(w: WatchdogDefault, args: &RunArgs) -> Result<WatchdogDefault, DaemonError> {
    let ms = w.hold_timeout_ms;
    let (lo, hi) = (MIN_HOLD.as_millis() as u64, MAX_HOLD.as_millis() as u64);
    if ms != 0 && !(lo..=hi).contains(&ms) {
        return Err(config_error(
            args,
            format!("watchdog.hold_timeout_ms = {ms}: allowed 0 (off) or {lo}..={hi}"),
        ));
    }
    Ok(w)
}

/// The simulator `--sim N` asks for: ids 1..=N at `--sim-baud`, with the
/// firmware of `--sim-firmware` (refused here, before anything starts).
fn sim_config(joints: u8, args: &RunArgs) -> Result<SimConfig, DaemonError> {
    let mut cfg = SimConfig::new((1..=joints).collect(), args.sim_baud);
    if let Some(spec) = &args.sim_firmware {
        cfg.firmware = Firmware::parse(spec)?;
    }
    if let Some(model) = &args.sim_adapter {
        cfg.adapter = AdapterModel::parse(model).map_err(SimError::BadAdapter)?;
    }
    cfg.write_delay = crate::sim::cli::parse_write_delay(args.sim_write_delay_us.as_deref())?;
    cfg.hard_stops = args
        .sim_hard_stop
        .iter()
        .map(|s| crate::sim::cli::parse_hard_stop(s))
        .collect::<Result<_, _>>()?;
    // The rest (the baud) is checked when the simulator starts.
    cfg.firmware.check_ids(&cfg.ids)?;
    if let Some((id, _)) = cfg.hard_stops.iter().find(|(id, _)| !cfg.ids.contains(id)) {
        return Err(SimError::BadHardStop(format!("device {id} is not on the bus")).into());
    }
    cfg.objects = args
        .sim_object
        .iter()
        .map(|s| crate::sim::cli::parse_object(s))
        .collect::<Result<_, _>>()?;
    if let Some(ob) = cfg.objects.iter().find(|o| !cfg.ids.contains(&o.id)) {
        return Err(SimError::BadObject(format!("device {} is not on the bus", ob.id)).into());
    }
    Ok(cfg)
}

/// A bus to start, and how it reaches its port.
type BusToStart = (BusConfig, Port);

/// How a bus reaches its port: a tty at its configured path, the
/// simulator's pty through the opener it gives, or the simulator's
/// in-memory line, handed in (there is no path to open).
enum Port {
    Path,
    Opened(Opener),
    HandedIn(Box<dyn Transport>),
}

/// Starts the simulator of `--sim` and the config of the bus that reaches
/// it: over a pty, opened by path like hardware; behind a USB adapter
/// model, over the in-memory line instead, with the line itself
/// ([`Simulator::spawn_for`] says why).
fn start_sim(sim_cfg: SimConfig) -> Result<(SimHandle, BusToStart), DaemonError> {
    let (ids, baud, joints) = (sim_cfg.ids.clone(), sim_cfg.baud, sim_cfg.ids.len());
    let firmware = sim_cfg.firmware.to_string();
    let adapter = sim_cfg.adapter;
    let (sim, memory) = Simulator::spawn_for(sim_cfg)?;
    let (path, port) = match (memory, sim.device_path(), sim.pty_opener()) {
        (Some(host), _, _) => (
            PathBuf::from(crate::sim::MEMORY_LINE_PATH),
            Port::HandedIn(Box::new(host)),
        ),
        (None, Some(path), Some(opener)) => (path, Port::Opened(opener)),
        _ => {
            return Err(DaemonError::Io {
                what: "simulator".into(),
                source: std::io::Error::other("the simulator has no device path"),
            })
        }
    };
    tracing::info!(path = %path.display(), joints, baud, %firmware, %adapter, "simulated bus started");
    let mut cfg = BusConfig::new(SIM_BUS_NAME, path, baud);
    cfg.ids = ids;
    // Neither a pty nor the in-memory line shows USB in sysfs: the bus is
    // told what the simulator models.
    cfg.adapter = AdapterSetting::Fixed(adapter);
    // The simulator shares the CPU with the daemon: on a busy machine its
    // replies can come milliseconds late, which is not a silent device.
    cfg.timing.reply_margin_us = SIM_REPLY_MARGIN_US;
    Ok((sim, (cfg, port)))
}

/// Runs the daemon until SIGINT or SIGTERM.
pub async fn run(args: RunArgs) -> Result<(), DaemonError> {
    let plan = plan(&args)?;
    raise_open_files_limit();
    // Bound before any bus opens: a second daemon on a taken address stops
    // there, without touching a port (nor sending a shutdown's disable).
    let listener = TcpListener::bind(plan.listen)
        .await
        .map_err(|e| listen_error(plan.listen, e))?;
    let mut configs: Vec<BusToStart> = plan
        .buses
        .into_iter()
        .map(|cfg| (cfg, Port::Path))
        .collect();
    let sim = match plan.sim {
        Some(sim_cfg) => {
            let (sim, bus) = start_sim(sim_cfg)?;
            configs.push(bus);
            Some(sim)
        }
        None => None,
    };
    let managed = configs
        .iter()
        .map(|(cfg, _)| (cfg.name.clone(), cfg.ids.clone()))
        .collect();
    let (handles, threads) = start_buses(configs)?;
    let addr = listener.local_addr().map_err(|e| DaemonError::Io {
        what: "listener address".into(),
        source: e,
    })?;
    // First line on stdout: scripts and tests read the port from it.
    println!("listening on http://{addr}");
    tracing::info!(%addr, auth = plan.token.is_some(), "serving the API");
    // One core, handed to HTTP and ROS 2 alike.
    let control = Arc::new(Control::new(handles, plan.limits));
    let mut control_options = plan.control;
    control_options.managed = managed;
    let ros2_stats = control_options.ros2.clone();
    // A fresh core and a fresh state have no options yet: neither call
    // can be refused.
    let _ = control.set_options(control_options);
    let state = AppState::new(control.clone(), plan.token);
    let mut http_options = plan.http;
    http_options.policy.listen = Some(addr);
    let _ = state.set_options(http_options);
    // The bridge lives until the daemon stops (dropped below: the ROS
    // graph sees its tokens go).
    let bridge = match (plan.ros2, ros2_stats) {
        (Some(cfg), Some(stats)) => Some(
            crate::ros2::start(control.clone(), cfg, stats)
                .map_err(|e| DaemonError::Policy(e.to_string()))?,
        ),
        _ => None,
    };
    serve(listener, &state).await?;
    wait_for_ws_close(&state).await;
    // The joints first: a recording still closing must not hold them.
    stop_buses(threads).await;
    stop_recordings(&state).await;
    // Leave the ROS graph once the buses are stopped.
    if let Some(bridge) = bridge {
        tracing::debug!(?bridge, "ROS 2 bridge closing");
    }
    drop(sim);
    tracing::info!("stopped");
    Ok(())
}

/// Serves the API until SIGINT or SIGTERM, then for at most
/// [`HTTP_DRAIN_TIMEOUT`] while the requests under way finish: a flood of
/// requests (or one that waits on a slow bus) cannot hold the shutdown,
/// and with it the joints' disable.
/// Every connection holds a file descriptor: at the common soft limit of
/// 1024 about a thousand idle connections leave no descriptor to accept the
/// e-stop's. The soft limit goes up to the hard one (what the service
/// manager allows); failing that is only logged.
fn raise_open_files_limit() {
    use nix::sys::resource::{getrlimit, setrlimit, Resource};
    match getrlimit(Resource::RLIMIT_NOFILE) {
        Ok((soft, hard)) if soft < hard => match setrlimit(Resource::RLIMIT_NOFILE, hard, hard) {
            Ok(()) => tracing::debug!(from = soft, to = hard, "open files limit raised"),
            Err(e) => tracing::warn!(soft, hard, "open files limit not raised: {e}"),
        },
        Ok(_) => {}
        Err(e) => tracing::warn!("open files limit not read: {e}"),
    }
}

async fn serve(listener: TcpListener, state: &AppState) -> Result<(), DaemonError> {
    let (signalled_tx, mut signalled) = tokio::sync::watch::channel(false);
    let ws_state = state.clone();
    let stopping = async move {
        shutdown_signal().await;
        // WebSocket sessions outlive the HTTP connections they upgraded:
        // tell them, so each client gets a close frame (1001).
        ws_state.ws().shut_down();
        let _ = signalled_tx.send(true);
    };
    let serving = axum::serve(crate::http::without_nagle(listener), app(state.clone()))
        .with_graceful_shutdown(stopping)
        .into_future();
    let drained = async {
        if signalled.wait_for(|s| *s).await.is_err() {
            return std::future::pending().await;
        }
        tokio::time::sleep(HTTP_DRAIN_TIMEOUT).await;
    };
    tokio::select! {
        served = serving => served.map_err(|e| DaemonError::Io {
            what: "HTTP server".into(),
            source: e,
        }),
        () = drained => {
            tracing::warn!("requests still open {HTTP_DRAIN_TIMEOUT:?} after the signal: \
                stopping without them");
            Ok(())
        }
    }
}

/// How long shutdown lets the requests under way finish.
const HTTP_DRAIN_TIMEOUT: Duration = Duration::from_secs(2);
/// How long shutdown waits for the recordings to write their summaries.
const RECORDINGS_CLOSE_TIMEOUT: Duration = Duration::from_secs(3);

/// Closes the recordings still running (bounded: a slow disk cannot hold
/// the exit); one not closed in time keeps its chunks, not its summary.
async fn stop_recordings(state: &AppState) {
    let closing = crate::control::recordings::stop_all(state.control());
    if tokio::time::timeout(RECORDINGS_CLOSE_TIMEOUT, closing)
        .await
        .is_err()
    {
        tracing::error!(
            "recordings not closed within {RECORDINGS_CLOSE_TIMEOUT:?}: left as they are"
        );
    }
}

/// How long shutdown waits for WebSocket sessions to send their close frames.
const WS_CLOSE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// Waits (bounded) until every WebSocket session has closed.
async fn wait_for_ws_close(state: &AppState) {
    let deadline = tokio::time::Instant::now() + WS_CLOSE_TIMEOUT;
    while state
        .ws()
        .connections
        .load(std::sync::atomic::Ordering::Relaxed)
        > 0
        && tokio::time::Instant::now() < deadline
    {
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
}

/// Starts one owner per bus; a port that is not there yet is retried by its owner.
fn start_buses(
    configs: Vec<BusToStart>,
) -> Result<(Vec<BusHandle>, Vec<crate::bus::BusThread>), DaemonError> {
    let mut handles = Vec::with_capacity(configs.len());
    let mut threads = Vec::with_capacity(configs.len());
    for (cfg, port) in configs {
        tracing::info!(bus = %cfg.name, path = %cfg.path.display(), baud = cfg.baud, "starting bus");
        let (handle, thread) = match port {
            Port::Path => spawn_bus(cfg)?,
            Port::Opened(opener) => spawn_bus_with(cfg, opener)?,
            Port::HandedIn(port) => spawn_bus_on(cfg, port)?,
        };
        handles.push(handle);
        threads.push(thread);
    }
    Ok((handles, threads))
}

/// Disables every joint and closes each port (the owner does both on
/// stop), every bus at once.
async fn stop_buses(threads: Vec<crate::bus::BusThread>) {
    let stops = threads.into_iter().map(|thread| async move {
        let stopping = tokio::task::spawn_blocking(move || thread.stop());
        if tokio::time::timeout(BUS_STOP_TIMEOUT, stopping)
            .await
            .is_err()
        {
            tracing::error!("a bus did not stop within {BUS_STOP_TIMEOUT:?}");
        }
    });
    futures_util::future::join_all(stops).await;
}

/// Resolves on the first SIGINT or SIGTERM.
async fn shutdown_signal() {
    let (Ok(mut int), Ok(mut term)) = (
        signal(SignalKind::interrupt()),
        signal(SignalKind::terminate()),
    ) else {
        tracing::error!("cannot install signal handlers; stop with SIGKILL");
        return std::future::pending().await;
    };
    tokio::select! {
        _ = int.recv() => tracing::info!("SIGINT: shutting down"),
        _ = term.recv() => tracing::info!("SIGTERM: shutting down"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(listen: &str) -> RunArgs {
        RunArgs {
            sim: Some(2),
            listen: Some(listen.parse().unwrap()),
            ..Default::default()
        }
    }

    #[test]
    fn non_loopback_needs_a_token_or_insecure() {
        assert!(matches!(
            plan(&args("0.0.0.0:8080")),
            Err(DaemonError::Insecure { .. })
        ));
        let mut with_token = args("0.0.0.0:8080");
        with_token.token = Some("t".into());
        assert!(plan(&with_token).is_ok());
        let mut insecure = args("0.0.0.0:8080");
        insecure.insecure = true;
        assert!(plan(&insecure).is_ok());
        assert!(plan(&args("127.0.0.1:0")).is_ok());
        let mut empty_token = args("[::]:80");
        empty_token.token = Some(String::new());
        assert!(plan(&empty_token).is_err(), "an empty token is no token");
    }

    #[test]
    fn default_bind_is_loopback_and_a_bus_is_required() {
        let p = plan(&RunArgs {
            sim: Some(1),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(p.listen.to_string(), DEFAULT_LISTEN);
        assert!(matches!(plan(&RunArgs::default()), Err(DaemonError::NoBus)));
    }

    #[test]
    fn sim_firmware_is_parsed_and_checked_against_the_simulated_ids() {
        let with = |spec: &str| {
            plan(&RunArgs {
                sim: Some(4),
                sim_firmware: Some(spec.into()),
                ..Default::default()
            })
        };
        let p = with("1-2=2.0.8").unwrap();
        let fw = &p.sim.as_ref().unwrap().firmware;
        assert_eq!(fw.revision_of(2).as_str(), "2.0.8");
        assert_eq!(fw.revision_of(3).as_str(), "2.0.1");
        let default = plan(&RunArgs {
            sim: Some(4),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(default.sim.unwrap().firmware, Firmware::default());
        for bad in ["2.0.9", "5=2.0.8", "1-4"] {
            let err = with(bad).unwrap_err();
            assert!(
                matches!(err, DaemonError::Sim(SimError::BadFirmware(_))),
                "{bad}: {err}"
            );
        }
        assert!(with("3-9=2.0.8")
            .unwrap_err()
            .to_string()
            .contains("not on the bus"));
    }

    #[test]
    fn config_file_gives_buses_and_limits_and_flags_win() {
        let dir = std::env::temp_dir().join(format!("jointd-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("jointd.toml");
        let text = "listen = \"0.0.0.0:9000\"\ntoken = \"file\"\n\
            [[bus]]\nname = \"left\"\npath = \"/dev/ttyUSB0\"\nbaud = 500000\n\
            [[limit]]\nbus = \"left\"\nids = [3]\nmin_deg = -45.0\nmax_deg = 45.0\n";
        std::fs::write(&path, text).unwrap();
        let p = plan(&RunArgs {
            config: Some(path.clone()),
            token: Some("flag".into()),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(p.token.as_deref(), Some("flag"));
        assert_eq!(p.listen.port(), 9000);
        assert_eq!(p.buses[0].name, "left");
        assert_eq!(p.limits.for_joint("left", 3).max_deg, 45.0);
        std::fs::write(&path, "bogus = 1\n").unwrap();
        let err = plan(&RunArgs {
            config: Some(path),
            sim: Some(1),
            ..Default::default()
        });
        assert!(matches!(err, Err(DaemonError::Config { .. })));
        let _ = std::fs::remove_dir_all(dir);
    }
}
