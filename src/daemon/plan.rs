//! Flags and config file checked into the daemon's plan: buses, soft
//! limits, token, the simulator, the core's and HTTP's options, ROS 2,
//! the live Foxglove view.
//! Everything a user can get wrong is refused here, before any port opens.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;

use super::args::{FileConfig, JointName, RunArgs, DEFAULT_LISTEN, SIM_BUS_NAME};
use super::error::DaemonError;
use super::tokens::{scoped_tokens, token_problem};
use crate::bus::BusConfig;
use crate::config_locate::{key_in_table_array, table_array_line};
use crate::control::foxglove_stats::FoxgloveStats;
use crate::control::limits::{LimitError, SoftLimits};
use crate::control::teleop::{WatchdogDefault, MAX_HOLD, MIN_HOLD};
use crate::http::policy::{RequestPolicy, DEFAULT_MAX_BODY_BYTES};
use crate::http::state::HttpOptions;
use crate::http::tokens::NamedToken;
use crate::protocol::is_device_id;
use crate::sim::{AdapterModel, Firmware, SimConfig, SimError};

/// Everything the daemon will run with, after file and flags are merged.
#[derive(Debug)]
pub struct Plan {
    pub listen: SocketAddr,
    /// The single token (`--token`, `token`): every scope.
    pub token: Option<String>,
    /// The scoped tokens of `[[tokens]]`.
    pub tokens: Vec<NamedToken>,
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
    /// Where the live Foxglove view listens, when on.
    pub foxglove: Option<SocketAddr>,
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

/// Merges the config file and the flags, and refuses unsafe combinations.
pub fn plan(args: &RunArgs) -> Result<Plan, DaemonError> {
    let file = match &args.config {
        Some(path) => load_file(path)?,
        None => FileConfig::default(),
    };
    let default_listen: SocketAddr = DEFAULT_LISTEN.parse().map_err(|_| DaemonError::NoBus)?;
    let listen = args.listen.or(file.listen).unwrap_or(default_listen);
    let token = token(args, &file)?;
    let tokens = scoped_tokens(&file.tokens, token.as_deref())?;
    let policy = request_policy(listen, args, &file)?;
    let foxglove = foxglove_addr(args, &file)?;
    if !listen.ip().is_loopback()
        && token.is_none()
        && tokens.is_empty()
        && !(args.insecure || file.insecure)
    {
        return Err(DaemonError::Insecure { addr: listen });
    }
    let (buses, sim, bus_names) = buses_of(file.buses, args)?;
    let hands = crate::hands::resolve(&file.hands, &bus_names)
        .map_err(|e| DaemonError::Policy(format!("[[hand]]: {e}")))?;
    let state_dir = args.state_dir.clone().or(file.state_dir);
    let poses = open_poses(hands, state_dir.as_deref())?;
    let hand_names: Vec<String> = poses.hands().iter().map(|h| h.name.clone()).collect();
    let ros2 = ros2_config(file.ros2, args, &bus_names, &hand_names)?;
    let control = crate::control::Options {
        ros2: ros2
            .as_ref()
            .map(|_| std::sync::Arc::new(crate::control::ros2_stats::Ros2Stats::default())),
        foxglove: foxglove.map(|_| std::sync::Arc::new(FoxgloveStats::default())),
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
        tokens,
        buses,
        limits: SoftLimits::new(file.limits)?,
        sim,
        control,
        http,
        ros2,
        foxglove,
    })
}

/// The configured buses, the simulator's, and every bus's name.
type PlannedBuses = (Vec<BusConfig>, Option<SimConfig>, Vec<String>);

/// The file's buses, then the flags', and the simulator's; their names.
/// At least one, or there is nothing to serve.
fn buses_of(mut buses: Vec<BusConfig>, args: &RunArgs) -> Result<PlannedBuses, DaemonError> {
    for spec in &args.buses {
        buses.push(BusConfig::parse_cli(spec)?);
    }
    let sim = args.sim.map(|n| sim_config(n, args)).transpose()?;
    if buses.is_empty() && sim.is_none() {
        return Err(DaemonError::NoBus);
    }
    let names = buses
        .iter()
        .map(|b| b.name.clone())
        .chain(sim.as_ref().map(|_| SIM_BUS_NAME.to_string()))
        .collect();
    Ok((buses, sim, names))
}

/// `--foxglove`, else `foxglove` of the file; `None`: the live view is off.
fn foxglove_addr(args: &RunArgs, file: &FileConfig) -> Result<Option<SocketAddr>, DaemonError> {
    if args.foxglove.is_some() {
        return Ok(args.foxglove);
    }
    let Some(text) = file.foxglove.as_deref() else {
        return Ok(None);
    };
    crate::foxglove::parse_addr(text)
        .map(Some)
        .map_err(|why| config_error(args, format!("foxglove = \"{text}\": {why}")))
}

/// The hands' poses and calibrations, in the state file under `state_dir`
/// (or in memory, said in the log when there are hands to lose).
fn open_poses(
    hands: Vec<crate::hands::Hand>,
    state_dir: Option<&std::path::Path>,
) -> Result<crate::hands::StateStore, DaemonError> {
    let poses = crate::hands::StateStore::open(hands, state_dir)
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
    Ok(poses)
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
    // Devices answer within their turnaround whatever else the host runs:
    // a simulator thread held off its CPU would look like devices falling
    // silent. Real-time where the system allows it (refused: logged).
    cfg.realtime = true;
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
    fn foxglove_is_off_by_default_and_the_flag_wins_over_the_file() {
        let dir = std::env::temp_dir().join(format!("jointd-fox-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("jointd.toml");
        let with = |text: &str, flag: Option<&str>| {
            std::fs::write(&path, text).unwrap();
            plan(&RunArgs {
                sim: Some(1),
                config: Some(path.clone()),
                foxglove: flag.map(|f| f.parse().unwrap()),
                ..Default::default()
            })
        };
        let off = with("", None).unwrap();
        assert_eq!(off.foxglove, None);
        assert!(off.control.foxglove.is_none(), "no counters when off");
        let on = with("foxglove = \"8765\"\n", None).unwrap();
        assert_eq!(on.foxglove.unwrap().to_string(), "127.0.0.1:8765");
        assert!(on.control.foxglove.is_some());
        let flag = with("foxglove = \"8765\"\n", Some("0.0.0.0:9000")).unwrap();
        assert_eq!(flag.foxglove.unwrap().to_string(), "0.0.0.0:9000");
        let err = with("foxglove = \"localhost\"\n", None).unwrap_err();
        assert!(matches!(err, DaemonError::Config { .. }), "{err}");
        assert!(
            err.to_string().contains("foxglove = \"localhost\""),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(dir);
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
