//! How close real delivery comes to the wire model on this machine: polls a
//! simulated device over a real pty, like the daemon would, and reports the
//! error of each stage in microseconds (`jointd sim --measure N`).
//!
//! - `arrival_lag`: host write returned → simulator timestamped the request
//!   (pty transfer + simulator wake-up; the model starts its clock here);
//! - `delivery_error`: reply bytes written to the pty − modelled instant of
//!   the reply's last byte (the simulator's own timing error);
//! - `end_to_end_error`: host saw the reply − host wrote the request −
//!   (frame + turnaround + frame): what a host measuring a poll sees.

use std::time::{Duration, Instant};

use serde::Serialize;

use crate::protocol::{Command, Config, InfoBlock, Message, StreamDecoder};
use crate::transport::tty::TtyPort;
use crate::transport::Transport;

use super::wire::frame_time;
use super::{SimConfig, SimError, Simulator, WireFrame};

/// A poll with no reply after this long counts as lost.
const POLL_TIMEOUT: Duration = Duration::from_millis(50);
/// Time for the power-up announcement to arrive before polling starts.
const SETTLE: Duration = Duration::from_millis(100);
const NANOS_PER_MICRO: f64 = 1000.0;

/// Percentiles of one error, µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub min: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub baud: u32,
    pub polls: usize,
    pub lost: usize,
    /// frame + turnaround + frame, µs.
    pub model_poll_us: f64,
    pub arrival_lag_us: Option<Spread>,
    pub delivery_error_us: Option<Spread>,
    pub end_to_end_error_us: Option<Spread>,
}

/// Percentiles of `samples` (ns) in µs; `None` when there are none.
pub fn spread(mut samples: Vec<i64>) -> Option<Spread> {
    if samples.is_empty() {
        return None;
    }
    samples.sort_unstable();
    let at = |q: f64| {
        let i = ((samples.len() - 1) as f64 * q).round() as usize;
        samples[i] as f64 / NANOS_PER_MICRO
    };
    Some(Spread {
        p50: at(0.5),
        p90: at(0.9),
        p99: at(0.99),
        max: at(1.0),
        min: at(0.0),
    })
}

fn signed_ns(later: Instant, earlier: Instant) -> i64 {
    if later >= earlier {
        i64::try_from((later - earlier).as_nanos()).unwrap_or(i64::MAX)
    } else {
        -i64::try_from((earlier - later).as_nanos()).unwrap_or(i64::MAX)
    }
}

/// Runs `polls` INFO_02 polls against device `cfg.ids[0]` over a pty.
pub fn run(cfg: SimConfig, polls: usize) -> Result<Report, SimError> {
    let baud = cfg.baud;
    let id = cfg.ids[0];
    let model = frame_time(baud) * 2 + cfg.turnaround;
    let sim = Simulator::spawn_pty(cfg)?;
    let path = sim.device_path().unwrap_or_default();
    let (mut port, _) = TtyPort::open(&path, baud).map_err(SimError::Pty)?;
    std::thread::sleep(SETTLE);
    port.discard_input().map_err(SimError::Pty)?;
    sim.clear_frame_log();
    let before = sim.delivery_errors_ns().len();
    let request = Command::Config(Config::read(id, InfoBlock::Info02)).encode();
    let mut host = Vec::with_capacity(polls);
    let mut lost = 0;
    for _ in 0..polls {
        match poll(&mut port, &request) {
            Some(times) => host.push(times),
            None => lost += 1,
        }
    }
    let log = sim.frame_log();
    let delivery = sim
        .delivery_errors_ns()
        .split_off(before.min(sim.delivery_errors_ns().len()));
    sim.shutdown();
    Ok(Report {
        baud,
        polls,
        lost,
        model_poll_us: model.as_secs_f64() * 1e6,
        arrival_lag_us: spread(arrival_lags(&log, &host)),
        delivery_error_us: spread(delivery),
        end_to_end_error_us: spread(
            host.iter()
                .map(|(w, r)| signed_ns(*r, *w) - model.as_nanos() as i64)
                .collect(),
        ),
    })
}

/// One poll: (write returned, reply decoded), or `None` if it never came.
fn poll(port: &mut TtyPort, request: &[u8]) -> Option<(Instant, Instant)> {
    port.write_all(request).ok()?;
    let written = Instant::now();
    let mut decoder = StreamDecoder::new();
    let mut buf = [0u8; 64];
    let deadline = written + POLL_TIMEOUT;
    loop {
        let left = deadline.checked_duration_since(Instant::now())?;
        let n = port.read_timeout(&mut buf, left).ok()?;
        decoder.push(&buf[..n]);
        if let Some(frame) = decoder.next_frame() {
            if matches!(Message::from_frame(&frame), Ok(Message::Reply(_))) {
                return Some((written, Instant::now()));
            }
        }
    }
}

/// Host write → simulator arrival, pairing host polls with logged requests.
fn arrival_lags(log: &[WireFrame], host: &[(Instant, Instant)]) -> Vec<i64> {
    let requests = log.iter().filter(|f| f.from_host);
    requests
        .zip(host)
        .map(|(f, (w, _))| signed_ns(f.start, *w))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_picks_percentiles_in_microseconds() {
        let s = spread((1..=100).map(|v| v * 1000).collect()).unwrap();
        assert_eq!((s.min, s.max), (1.0, 100.0));
        assert!((s.p50 - 50.0).abs() <= 1.0 && (s.p99 - 99.0).abs() <= 1.0);
        assert!(spread(Vec::new()).is_none());
    }
}
