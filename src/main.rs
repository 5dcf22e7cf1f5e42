//! The `jointd` binary: command line, logging, then the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// jointd: a gateway daemon for RS-485 servo joint modules.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Decode or encode single frames (for reading a serial capture by hand).
    #[command(subcommand)]
    Frame(FrameCommand),
    /// Run a simulated bus of joint modules on a pseudo-terminal (path on stdout;
    /// stdin takes fault commands, `help` lists them).
    Sim(jointd::sim::cli::SimArgs),
    /// Measure the bus engine against the simulator: occupancy, collisions,
    /// per-joint rates, setpoint-to-wire latency, daemon CPU.
    Bench(jointd::bench::BenchArgs),
}

#[derive(Subcommand, Debug)]
enum FrameCommand {
    /// Print one JSON object per frame found in a hex dump (spaces optional).
    Decode {
        /// Hex bytes, e.g. "55 AA 00 14 00 02 01 00 00 00 75 4F 00 00 FA 05 AC 95 00 00".
        hex: String,
    },
    /// Print the 20 bytes of the host→device frame a JSON object describes.
    Encode {
        /// e.g. '{"kind":"control","dev_id":1,"en":"set_ref","pos_deg":90,"spd_rpm":1000}'.
        json: String,
    },
}

/// Bad input to a `frame` command: message on stderr, exit status 2.
const EXIT_BAD_INPUT: u8 = 2;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Frame(cmd) => run_frame(cmd),
        Command::Sim(args) => match jointd::sim::cli::run(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("jointd sim: {e}");
                ExitCode::FAILURE
            }
        },
        Command::Bench(args) => match jointd::bench::run(&args) {
            Ok(true) => ExitCode::SUCCESS,
            Ok(false) => ExitCode::FAILURE,
            Err(e) => {
                eprintln!("jointd bench: {e}");
                ExitCode::FAILURE
            }
        },
    }
}

fn run_frame(cmd: FrameCommand) -> ExitCode {
    let result = match cmd {
        FrameCommand::Decode { hex } => {
            jointd::cli::decode_hex(&hex).map(|(lines, stats, trailing)| {
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
