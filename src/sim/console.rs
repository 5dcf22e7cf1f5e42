//! Run-time control of `jointd sim` from its stdin, one command a line, so
//! faults can be switched while a daemon is attached:
//!
//! ```text
//! unplug | replug | clear | stats | devices | help
//! power-cycle ID          under-voltage ID on|off
//! stall ID [DEG]          corrupt RATE
//! object ID DEG NM_PER_DEG | object ID off    (an elastic object; off pulls it away)
//! drop RATE [ID]          extra-turnaround MICROS
//! write-delay P50,P99[,P99.9],MAX | off     (µs; behind an adapter model)
//! echo on|off             stuck-count on|off  (the adapter echoes; its count never falls)
//! noise MILLIS | noise off  (a frame of random bytes to the host every MILLIS ms)
//! ```
//! Answers go to stderr (stdout carries only the device path).

use std::io::BufRead;
use std::time::Duration;

use super::{Fault, SimHandle};

pub(crate) const HELP: &str = "commands: unplug | replug | clear | stats | devices | help | \
power-cycle ID | under-voltage ID on|off | stall ID [DEG] | \
object ID DEG NM_PER_DEG | object ID off | corrupt RATE | \
drop RATE [ID] | extra-turnaround MICROS | miss-control ID COUNT | \
write-delay P50,P99[,P99.9],MAX|off | echo on|off | stuck-count on|off | noise MILLIS|off";

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ConsoleCmd {
    Fault(Fault),
    Stats,
    Devices,
    Help,
}

fn num<T: std::str::FromStr>(word: Option<&str>, what: &str) -> Result<T, String> {
    let w = word.ok_or_else(|| format!("missing {what}"))?;
    w.parse()
        .map_err(|_| format!("`{w}` is not a valid {what}"))
}

/// Parses one console line.
pub(crate) fn parse(line: &str) -> Result<ConsoleCmd, String> {
    let mut words = line.split_whitespace();
    let cmd = words.next().unwrap_or("help");
    let fault = match cmd {
        "stats" => return Ok(ConsoleCmd::Stats),
        "devices" => return Ok(ConsoleCmd::Devices),
        "help" => return Ok(ConsoleCmd::Help),
        "unplug" => Fault::Unplug,
        "replug" => Fault::Replug,
        "clear" => Fault::ClearAll,
        "power-cycle" => Fault::PowerCycle {
            dev_id: num(words.next(), "device id")?,
        },
        "stall" => Fault::Stall {
            dev_id: num(words.next(), "device id")?,
            at_deg: words.next().map(|w| num(Some(w), "angle")).transpose()?,
        },
        "under-voltage" => Fault::UnderVoltage {
            dev_id: num(words.next(), "device id")?,
            on: match words.next() {
                Some("on") => true,
                Some("off") => false,
                _ => return Err("under-voltage ID on|off".into()),
            },
        },
        "object" => object(words.next(), words.next(), words.next())?,
        "corrupt" => Fault::CorruptRate(num(words.next(), "rate")?),
        "drop" => Fault::DropReplies {
            rate: num(words.next(), "rate")?,
            dev_id: words
                .next()
                .map(|w| num(Some(w), "device id"))
                .transpose()?,
        },
        "extra-turnaround" => {
            Fault::ExtraTurnaround(Duration::from_micros(num(words.next(), "microseconds")?))
        }
        "miss-control" => Fault::MissControl {
            dev_id: num(words.next(), "device id")?,
            count: num(words.next(), "frame count")?,
        },
        "write-delay" => match words.next() {
            Some("off") => Fault::WriteDelay(None),
            Some(spec) => Fault::WriteDelay(Some(super::WriteDelay::parse(spec)?)),
            None => return Err("write-delay P50,P99[,P99.9],MAX | off".into()),
        },
        "echo" => Fault::Echo(on_off(words.next(), "echo on|off")?),
        "noise" => Fault::Noise(match words.next() {
            Some("off") => None,
            w => Some(Duration::from_millis(num(w, "period in ms (or off)")?)),
        }),
        "stuck-count" => Fault::StuckCount(on_off(words.next(), "stuck-count on|off")?),
        other => return Err(format!("unknown command `{other}`; {HELP}")),
    };
    Ok(ConsoleCmd::Fault(fault))
}

/// `on` or `off`; otherwise the usage.
fn on_off(word: Option<&str>, usage: &str) -> Result<bool, String> {
    match word {
        Some("on") => Ok(true),
        Some("off") => Ok(false),
        _ => Err(usage.to_string()),
    }
}

/// `object ID DEG NM_PER_DEG` puts an object; `object ID off` removes it.
fn object(id: Option<&str>, deg: Option<&str>, k: Option<&str>) -> Result<Fault, String> {
    let dev_id = num(id, "device id")?;
    if deg == Some("off") {
        return Ok(Fault::RemoveObject { dev_id });
    }
    let (at_deg, nm_per_deg): (f64, f64) = (num(deg, "angle")?, num(k, "stiffness (N·m/°)")?);
    if !at_deg.is_finite() || !nm_per_deg.is_finite() || nm_per_deg <= 0.0 {
        return Err("object ID DEG NM_PER_DEG: a finite angle and a stiffness above 0".into());
    }
    Ok(Fault::Object {
        dev_id,
        at_deg,
        nm_per_deg,
    })
}

/// Executes one line against the simulator; the answer to print.
pub(crate) fn execute(sim: &SimHandle, line: &str) -> String {
    match parse(line) {
        Ok(ConsoleCmd::Fault(f)) => {
            sim.inject(f);
            format!("ok: {f:?}")
        }
        Ok(ConsoleCmd::Stats) => serde_json::to_string(&sim.stats()).unwrap_or_default(),
        Ok(ConsoleCmd::Devices) => serde_json::to_string(&sim.devices()).unwrap_or_default(),
        Ok(ConsoleCmd::Help) => HELP.to_string(),
        Err(e) => format!("error: {e}"),
    }
}

/// Serves stdin in a background thread until it closes.
pub(crate) fn spawn(sim: SimHandle) {
    let spawned = std::thread::Builder::new()
        .name("jointd-sim-console".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if !line.trim().is_empty() {
                    eprintln!("{}", execute(&sim, &line));
                }
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("no simulator console: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_to_faults() {
        assert_eq!(parse("unplug"), Ok(ConsoleCmd::Fault(Fault::Unplug)));
        assert_eq!(
            parse("stall 3 12.5"),
            Ok(ConsoleCmd::Fault(Fault::Stall {
                dev_id: 3,
                at_deg: Some(12.5)
            }))
        );
        assert_eq!(
            parse("drop 0.5"),
            Ok(ConsoleCmd::Fault(Fault::DropReplies {
                dev_id: None,
                rate: 0.5
            }))
        );
        assert_eq!(
            parse("under-voltage 2 off"),
            Ok(ConsoleCmd::Fault(Fault::UnderVoltage {
                dev_id: 2,
                on: false
            }))
        );
        assert_eq!(
            parse("miss-control 4 3"),
            Ok(ConsoleCmd::Fault(Fault::MissControl {
                dev_id: 4,
                count: 3
            }))
        );
        assert!(parse("miss-control 4").is_err());
        assert_eq!(
            parse("object 2 30 0.05"),
            Ok(ConsoleCmd::Fault(Fault::Object {
                dev_id: 2,
                at_deg: 30.0,
                nm_per_deg: 0.05
            }))
        );
        assert_eq!(
            parse("object 2 off"),
            Ok(ConsoleCmd::Fault(Fault::RemoveObject { dev_id: 2 }))
        );
        assert!(parse("object 2 30 0").is_err());
        assert!(parse("object 2 30").is_err());
        assert_eq!(parse("echo on"), Ok(ConsoleCmd::Fault(Fault::Echo(true))));
        assert_eq!(
            parse("stuck-count off"),
            Ok(ConsoleCmd::Fault(Fault::StuckCount(false)))
        );
        assert!(parse("echo").is_err());
        assert_eq!(
            parse("noise 20"),
            Ok(ConsoleCmd::Fault(Fault::Noise(Some(
                Duration::from_millis(20)
            ))))
        );
        assert_eq!(
            parse("noise off"),
            Ok(ConsoleCmd::Fault(Fault::Noise(None)))
        );
        assert!(parse("noise").is_err());
        assert_eq!(parse("stats"), Ok(ConsoleCmd::Stats));
        assert!(parse("stall x").is_err());
        assert!(parse("explode").is_err());
        assert!(parse("under-voltage 2").is_err());
    }
}
