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
//!
//! It also reports line occupancy: of the poll loop itself (request, reply
//! and the host's own reaction gap), of a line saturated with back-to-back
//! broadcasts, and of an idle line.

use std::time::{Duration, Instant};

use serde::Serialize;

use crate::protocol::{BroadcastPos, Command, Config, Group, InfoBlock, Message, StreamDecoder};
use crate::transport::tty::TtyPort;
use crate::transport::Transport;

use super::wire::frame_time;
use super::{SimConfig, SimError, SimHandle, SimStats, Simulator, WireFrame};

/// A poll with no reply after this long counts as lost.
const POLL_TIMEOUT: Duration = Duration::from_millis(50);
/// Time for the power-up announcement to arrive before polling starts.
const SETTLE: Duration = Duration::from_millis(100);
const NANOS_PER_MICRO: f64 = 1000.0;
/// Broadcasts written in the saturation run (≈ 1.6 s of wire at 500000 baud).
const SATURATION_FRAMES: u64 = 4000;
const SATURATION_TIMEOUT: Duration = Duration::from_secs(60);
const STATS_POLL: Duration = Duration::from_micros(200);
const IDLE_SPAN: Duration = Duration::from_millis(300);

/// Percentiles of one error, µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(crate) struct Spread {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub min: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Report {
    pub baud: u32,
    pub polls: usize,
    pub lost: usize,
    /// frame + turnaround + frame, µs.
    pub model_poll_us: f64,
    pub arrival_lag_us: Option<Spread>,
    pub delivery_error_us: Option<Spread>,
    pub end_to_end_error_us: Option<Spread>,
    pub poll_loop_occupancy: f64,
    pub saturated_occupancy: f64,
    pub idle_occupancy: f64,
}

/// Percentiles of `samples` (ns) in µs; `None` when there are none.
pub(crate) fn spread(mut samples: Vec<i64>) -> Option<Spread> {
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

/// Runs `polls` INFO_02 polls against the first device over a pty, then the
/// idle and saturation runs.
pub(crate) fn run(cfg: SimConfig, polls: usize) -> Result<Report, SimError> {
    cfg.validate()?;
    let baud = cfg.baud;
    let id = cfg.ids.first().copied().unwrap_or(1);
    let model = frame_time(baud) * 2 + cfg.turnaround;
    let sim = Simulator::spawn_pty(cfg)?;
    let path = sim.device_path().unwrap_or_default();
    let (mut port, _) = TtyPort::open(&path, baud).map_err(SimError::Pty)?;
    std::thread::sleep(SETTLE);
    port.discard_input().map_err(SimError::Pty)?;
    sim.clear_frame_log();
    let before = sim.delivery_errors_ns().len();
    let loop_from = sim.stats();
    let host = poll_loop(&mut port, id, polls);
    let loop_to = sim.stats();
    let answered: Vec<(Instant, Instant)> = host
        .iter()
        .filter_map(|p| Some((p.written, p.answered?)))
        .collect();
    let log = sim.frame_log();
    let mut delivery = sim.delivery_errors_ns();
    let delivery = delivery.split_off(before.min(delivery.len()));
    let idle_occupancy = idle(&sim);
    let saturated_occupancy = saturate(&sim, &mut port)?;
    sim.shutdown();
    let model_ns = i64::try_from(model.as_nanos()).unwrap_or(i64::MAX);
    Ok(Report {
        baud,
        polls,
        lost: polls - answered.len(),
        model_poll_us: model.as_secs_f64() * 1e6,
        arrival_lag_us: spread(arrival_lags(&log, &host)),
        delivery_error_us: spread(delivery),
        end_to_end_error_us: spread(
            answered
                .iter()
                .map(|(w, r)| signed_ns(*r, *w) - model_ns)
                .collect(),
        ),
        poll_loop_occupancy: SimStats::occupancy(&loop_from, &loop_to),
        saturated_occupancy,
        idle_occupancy,
    })
}

/// Polls back to back (every request that was written).
fn poll_loop(port: &mut TtyPort, id: u8, polls: usize) -> Vec<Poll> {
    let request = Command::Config(Config::read(id, InfoBlock::Info02)).encode();
    (0..polls).filter_map(|_| poll(port, &request)).collect()
}

/// One poll: when the write returned and when the reply was decoded.
#[derive(Debug, Clone, Copy)]
struct Poll {
    written: Instant,
    answered: Option<Instant>,
}

/// Sends one request and waits for its reply. After a loss it lets a late
/// reply arrive and throws it away, so it cannot pass for the next one's.
fn poll(port: &mut TtyPort, request: &[u8]) -> Option<Poll> {
    port.write_all(request).ok()?;
    let written = Instant::now();
    let answered = await_reply(port, written + POLL_TIMEOUT);
    if answered.is_none() {
        std::thread::sleep(POLL_TIMEOUT);
        port.discard_input().ok()?;
    }
    Some(Poll { written, answered })
}

fn await_reply(port: &mut TtyPort, deadline: Instant) -> Option<Instant> {
    let mut decoder = StreamDecoder::new();
    let mut buf = [0u8; 64];
    loop {
        let left = deadline.checked_duration_since(Instant::now())?;
        let n = port.read_timeout(&mut buf, left).ok()?;
        decoder.push(&buf[..n]);
        if let Some(frame) = decoder.next_frame() {
            if matches!(Message::from_frame(&frame), Ok(Message::Reply(_))) {
                return Some(Instant::now());
            }
        }
    }
}

/// Occupancy of a line nobody talks on, over [`IDLE_SPAN`].
fn idle(sim: &SimHandle) -> f64 {
    let from = sim.stats();
    std::thread::sleep(IDLE_SPAN);
    SimStats::occupancy(&from, &sim.stats())
}

/// Occupancy while the host writes broadcasts faster than the wire takes them,
/// measured between the simulator having taken a quarter and three quarters of them.
fn saturate(sim: &SimHandle, port: &mut TtyPort) -> Result<f64, SimError> {
    let frame = Command::BroadcastPos(BroadcastPos {
        group: Group::Low,
        pos_ref: [0; 8],
    })
    .encode();
    let bytes: Vec<u8> = (0..SATURATION_FRAMES).flat_map(|_| frame).collect();
    let start = sim.stats().host_frames;
    let (quarter, three) = (
        start + SATURATION_FRAMES / 4,
        start + 3 * SATURATION_FRAMES / 4,
    );
    let (a, b) = std::thread::scope(|s| {
        let writer = s.spawn(|| port.write_all(&bytes));
        let a = wait_stats(sim, |st| st.host_frames >= quarter);
        let b = wait_stats(sim, |st| st.host_frames >= three);
        // A failed write shows up as the counts never being reached.
        let _ = writer.join();
        (a, b)
    });
    match (a, b) {
        (Some(a), Some(b)) => Ok(SimStats::occupancy(&a, &b)),
        _ => Err(SimError::Pty(std::io::Error::other(
            "saturation run did not finish",
        ))),
    }
}

/// Polls stats until `done` holds (bounded by [`SATURATION_TIMEOUT`]).
fn wait_stats(sim: &SimHandle, done: impl Fn(&SimStats) -> bool) -> Option<SimStats> {
    let deadline = Instant::now() + SATURATION_TIMEOUT;
    while Instant::now() < deadline {
        let s = sim.stats();
        if done(&s) {
            return Some(s);
        }
        std::thread::sleep(STATS_POLL);
    }
    None
}

/// Host write → simulator arrival, pairing host polls with logged requests.
fn arrival_lags(log: &[WireFrame], host: &[Poll]) -> Vec<i64> {
    let requests = log.iter().filter(|f| f.from_host);
    requests
        .zip(host)
        .map(|(f, p)| signed_ns(f.start, p.written))
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
