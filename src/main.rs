//! The `jointd` binary: command line, logging, then the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// jointd: a gateway daemon for RS-485 servo joint modules.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// With no subcommand, jointd runs the daemon (same flags as `jointd run`).
    #[command(flatten)]
    run: jointd::daemon::RunArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Decode or encode single frames (for reading a serial capture by hand).
    #[command(subcommand)]
    Frame(FrameCommand),
    /// Run a simulated bus of joint modules on a pseudo-terminal (path on stdout;
    /// stdin takes fault commands, `help` lists them).
    Sim(jointd::sim::cli::SimArgs),
    /// Run the daemon: buses, REST API, graceful shutdown on SIGINT/SIGTERM (the default).
    Run(jointd::daemon::RunArgs),
    /// Check a real bus before running jointd on it: the port, the adapter
    /// (latency timer, output count, echo), the line, the baud the devices
    /// answer at, each device, ids on two devices; then the bus config to
    /// use and its rates. Sends only reads. Exit status 1 when a check
    /// failed, 3 when another process holds the port (left untouched).
    Doctor(jointd::doctor::DoctorArgs),
    /// Print the OpenAPI document of the REST API (as checked in under openapi/).
    Openapi,
    /// Record a running daemon's buses to an MCAP file (joint states, raw
    /// frames, events, commanded targets) for a duration or until Ctrl-C.
    Record(jointd::record::client::RecordArgs),
    /// Measure the bus engine against the simulator: occupancy, collisions,
    /// per-joint rates, setpoint-to-wire latency, daemon CPU.
    #[cfg(feature = "bench")]
    Bench(jointd::bench::BenchArgs),
    /// Not in this build: the bench is compiled in with `--features bench`.
    /// Taken here (hidden, any arguments) so that `jointd bench` says how
    /// to get it instead of clap's "unrecognized subcommand".
    #[cfg(not(feature = "bench"))]
    #[command(hide = true, disable_help_flag = true)]
    Bench {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<std::ffi::OsString>,
    },
}

#[derive(Subcommand, Debug)]
enum FrameCommand {
    /// Print one JSON object per frame found in a hex dump (spaces optional).
    Decode {
        /// Hex bytes, e.g. "55 AA 00 14 00 02 01 00 00 00 75 4F 00 00 FA 05 AC 95 00 00".
        #[arg(required_unless_present = "mcap", conflicts_with = "mcap")]
        hex: Option<String>,
        /// Instead: list the frames of an MCAP recording (`jointd record`).
        #[arg(long, value_name = "FILE")]
        mcap: Option<std::path::PathBuf>,
    },
    /// Print the 20 bytes of the host→device frame a JSON object describes.
    Encode {
        /// e.g. '{"kind":"control","dev_id":1,"en":"set_ref","pos_deg":90,"spd_rpm":1000}'.
        json: String,
    },
}

/// Bad input to a `frame` command, or a subcommand this build lacks:
/// message on stderr, exit status 2.
const EXIT_BAD_INPUT: u8 = 2;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        None => run_daemon(cli.run),
        Some(Command::Run(args)) => run_daemon(args),
        Some(Command::Openapi) => {
            print!("{}", jointd::http::api::document_json());
            ExitCode::SUCCESS
        }
        Some(Command::Frame(cmd)) => run_frame(cmd),
        Some(Command::Doctor(args)) => ExitCode::from(jointd::doctor::run(&args)),
        Some(Command::Record(args)) => match jointd::record::client::run(&args) {
            Ok(status) => {
                println!("{status}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("jointd record: {e}");
                ExitCode::FAILURE
            }
        },
        Some(Command::Sim(args)) => match jointd::sim::cli::run(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("jointd sim: {e}");
                ExitCode::FAILURE
            }
        },
        #[cfg(feature = "bench")]
        Some(Command::Bench(args)) => match jointd::bench::run(&args) {
            Ok(true) => ExitCode::SUCCESS,
            Ok(false) => ExitCode::FAILURE,
            Err(e) => {
                eprintln!("jointd bench: {e}");
                ExitCode::FAILURE
            }
        },
        #[cfg(not(feature = "bench"))]
        Some(Command::Bench { .. }) => {
            eprintln!(
                "jointd bench needs a build with --features bench: \
                 cargo run --release --features bench -- bench [ARGS]"
            );
            ExitCode::from(EXIT_BAD_INPUT)
        }
    }
}

fn run_daemon(args: jointd::daemon::RunArgs) -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("jointd: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(jointd::daemon::run(args)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("jointd: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run_frame(cmd: FrameCommand) -> ExitCode {
    let result = match cmd {
        FrameCommand::Decode {
            mcap: Some(path), ..
        } => jointd::cli::decode_mcap(&path).map(|lines| {
            for line in lines {
                println!("{line}");
            }
        }),
        FrameCommand::Decode { hex, .. } => {
            jointd::cli::decode_hex(&hex.unwrap_or_default()).map(|(lines, stats, trailing)| {
                for line in lines {
                    println!("{line}");
                }
                if stats.skipped_bytes > 0 || trailing > 0 {
                    eprintln!(
                        "note: {} bytes skipped ({} CRC errors), {} trailing bytes form no frame",
                        stats.skipped_bytes, stats.crc_errors, trailing
                    );
                }
            })
        }
        FrameCommand::Encode { json } => {
            jointd::cli::encode_json(&json).map(|hex| println!("{hex}"))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("jointd frame: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
    }
}
