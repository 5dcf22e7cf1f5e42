//! `jointd bench --ws`: the WebSocket path, measured in one run against the
//! engine alone. Three phases share one simulated bus:
//!
//! 1. **engine**: the in-process client writes every joint's target at the
//!    rate (the bus engine's own figure);
//! 2. **ws**: the same stream from a WebSocket client through `/api/v1/ws`;
//! 3. **ws + telemetry**: phase 2 with N telemetry clients subscribed to
//!    every joint at their rate;
//!
//! then, the bus stopped, the same number of sends of the same size alone
//! ([`super::send_floor`]): what the kernel takes of phase 3 whatever the
//! daemon does.
//!
//! Latency is client send → last byte of the carrying frame on the simulated
//! wire (the angle encodes the write, as in `jointd bench`). Daemon CPU is the
//! bus owner's and the HTTP/WebSocket runtime's threads; the clients' and the
//! simulator's threads are reported apart. Clients are plain threads with a
//! blocking socket, so their timing does not depend on tokio's timer.

mod phase;
mod report;
mod socket;
mod telemetry;

use std::fmt::Write as _;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tungstenite::Message;

use crate::bench::analysis;
use crate::bench::args::{BenchArgs, BenchError, SIM_THREAD};
use crate::bench::client::{angle_of, Client, Pacer, Write, CLIENT_THREAD};
use crate::bench::rig::setup;
use crate::bench::{cpu, send_floor};
use crate::bus::{BusHandle, THREAD_PREFIX};
use crate::control::Control;
use crate::http::{app, AppState};
use crate::sim::{SimHandle, SimStats};
use phase::Phase;
use report::report;
use socket::{connect, Socket, HTTP_THREAD, TELEMETRY_THREAD, TELEOP_THREAD};
use telemetry::Telemetry;

/// Speed limit the WebSocket client sends, output °/s (about the vendor's
/// recommended 20000 rotor rpm).
const SPEED_DPS: f64 = 200.0;
/// Worker threads of the HTTP/WebSocket runtime (the daemon's default on 2 cores).
const HTTP_WORKERS: usize = 2;

pub fn run(args: &BenchArgs) -> Result<bool, BenchError> {
    let baud = args.bauds.first().copied().unwrap_or(500_000);
    let ids: Vec<u8> = (1..=args.joints).collect();
    let period = Duration::from_secs_f64(1.0 / f64::from(args.rate_hz));
    let (sim, bus, thread) = setup(args, baud, &ids)?;
    let (runtime, url) = serve(bus.clone())?;
    let phases = [
        engine_phase(args, &sim, &bus, &ids, period)?,
        ws_phase(args, &sim, &url, &ids, period, 0)?,
        ws_phase(args, &sim, &url, &ids, period, args.telemetry_clients)?,
    ];
    runtime.shutdown_timeout(Duration::from_secs(1));
    thread.stop();
    sim.shutdown();
    // With the bus stopped: the sends alone, on a quiet process.
    // A floor that cannot be measured (no loopback sockets left) costs its
    // two lines, not the three phases' report.
    let floor = match phases[2].telemetry_len {
        Some(len) if args.telemetry_clients > 0 => send_floor::measure(
            args.telemetry_clients,
            args.telemetry_hz,
            len.round() as usize,
            Duration::from_secs_f64(args.warmup),
            Duration::from_secs_f64(args.seconds),
        )
        .map_err(|e| eprintln!("the sends alone could not be measured: {e}"))
        .ok(),
        _ => None,
    };
    let (text, passed) = report(args, baud, &phases, floor);
    println!("{text}");
    Ok(passed)
}

/// The REST/WebSocket app on 127.0.0.1:0 in its own named runtime.
fn serve(bus: BusHandle) -> Result<(tokio::runtime::Runtime, String), BenchError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(HTTP_WORKERS)
        .thread_name(HTTP_THREAD)
        .enable_all()
        .build()?;
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    listener.set_nonblocking(true)?;
    let addr = listener.local_addr()?;
    rt.spawn(async move {
        match tokio::net::TcpListener::from_std(listener) {
            Ok(l) => {
                // As the daemon serves: without Nagle.
                let l = crate::http::without_nagle(l);
                if let Err(e) = axum::serve(
                    l,
                    app(AppState::new(
                        Arc::new(Control::new(vec![bus], Default::default())),
                        None,
                    )),
                )
                .await
                {
                    eprintln!("bench server: {e}");
                }
            }
            Err(e) => eprintln!("bench server: {e}"),
        }
    });
    Ok((rt, format!("ws://{addr}/api/v1/ws")))
}

fn engine_phase(
    args: &BenchArgs,
    sim: &SimHandle,
    bus: &BusHandle,
    ids: &[u8],
    period: Duration,
) -> Result<Phase, BenchError> {
    let client = Client::start(bus.clone(), ids.to_vec(), period, 0)?;
    let (w, ()) = window(args, sim, || (), || client.finish())?;
    Ok(w.into_phase(ids, None, None))
}

fn ws_phase(
    args: &BenchArgs,
    sim: &SimHandle,
    url: &str,
    ids: &[u8],
    period: Duration,
    telemetry_clients: usize,
) -> Result<Phase, BenchError> {
    let watchers = Telemetry::start(url, telemetry_clients, args.telemetry_hz)?;
    let teleop = Teleop::start(url, ids.to_vec(), period)?;
    let (w, started) = window(args, sim, || watchers.counts(), || teleop.finish())?;
    let telemetry = watchers.rates(&started, w.elapsed());
    let telemetry_len = watchers.mean_len();
    watchers.stop();
    Ok(w.into_phase(ids, telemetry, telemetry_len))
}

/// What a window's simulator, CPU and client recorded.
struct Window {
    stats: [SimStats; 2],
    cpu: [Vec<Duration>; 2],
    writes: Vec<Write>,
    log: Vec<crate::sim::WireFrame>,
    rss_mb: f64,
}

const CPU_THREADS: [&str; 6] = [
    THREAD_PREFIX,
    HTTP_THREAD,
    SIM_THREAD,
    CLIENT_THREAD,
    TELEOP_THREAD,
    TELEMETRY_THREAD,
];

fn cpu_now() -> Vec<Duration> {
    cpu::snapshot(&CPU_THREADS)
}

/// Warm-up, then the measured window. `mark` runs as the window opens
/// (its result is returned beside the window); `finish` stops the client
/// and returns its writes.
fn window<T>(
    args: &BenchArgs,
    sim: &SimHandle,
    mark: impl FnOnce() -> T,
    finish: impl FnOnce() -> Vec<Write>,
) -> Result<(Window, T), BenchError> {
    std::thread::sleep(Duration::from_secs_f64(args.warmup));
    sim.clear_frame_log();
    let (s0, c0, marked) = (sim.stats(), cpu_now(), mark());
    std::thread::sleep(Duration::from_secs_f64(args.seconds));
    let (s1, c1) = (sim.stats(), cpu_now());
    let writes = finish();
    let w = Window {
        stats: [s0, s1],
        cpu: [c0, c1],
        writes,
        log: sim.frame_log(),
        rss_mb: rss_mb(),
    };
    Ok((w, marked))
}

impl Window {
    fn elapsed(&self) -> Duration {
        self.stats[1].at.saturating_duration_since(self.stats[0].at)
    }

    fn share(&self, which: &[usize]) -> f64 {
        let used: Duration = which
            .iter()
            .map(|&i| self.cpu[1][i].saturating_sub(self.cpu[0][i]))
            .sum();
        used.as_secs_f64() / self.elapsed().as_secs_f64().max(f64::EPSILON)
    }

    fn into_phase(
        self,
        ids: &[u8],
        telemetry: Option<(f64, f64, u64)>,
        telemetry_len: Option<f64>,
    ) -> Phase {
        let (s0, s1) = (&self.stats[0], &self.stats[1]);
        Phase {
            occupancy: SimStats::occupancy(s0, s1),
            collisions: s1.collisions.saturating_sub(s0.collisions),
            analysis: analysis::analyse(&self.log, &self.writes, ids, s0.at, s1.at),
            cpu_daemon: self.share(&[0, 1]),
            cpu_clients: self.share(&[3, 4, 5]),
            rss_mb: self.rss_mb,
            telemetry,
            telemetry_len,
        }
    }
}

/// Resident memory of the whole process (daemon, simulator and clients), MiB.
fn rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .map(str::to_owned)
        })
        .and_then(|l| {
            l.split_whitespace()
                .nth(1)
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// The teleoperation client: every joint's target each period, as one
/// `setpoints` batch; the angle encodes the write's count.
struct Teleop {
    stop: Arc<AtomicBool>,
    join: JoinHandle<Vec<Write>>,
}

impl Teleop {
    fn start(url: &str, ids: Vec<u8>, period: Duration) -> Result<Teleop, BenchError> {
        let ws = connect(url)?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let join = std::thread::Builder::new()
            .name(TELEOP_THREAD.into())
            .spawn(move || stream(ws, &ids, period, &flag))?;
        Ok(Teleop { stop, join })
    }

    fn finish(self) -> Vec<Write> {
        self.stop.store(true, Ordering::Release);
        self.join.join().unwrap_or_default()
    }
}

fn batch(ids: &[u8], n: u64) -> String {
    let deg = f64::from(angle_of(n)) / 128.0;
    let mut s = String::from(r#"{"type":"setpoints","targets":["#);
    for (i, id) in ids.iter().enumerate() {
        let sep = if i == 0 { "" } else { "," };
        let _ = write!(
            s,
            r#"{sep}{{"id":{id},"position_deg":{deg},"speed_dps":{SPEED_DPS}}}"#
        );
    }
    s.push_str("]}");
    s
}

fn stream(mut ws: Socket, ids: &[u8], period: Duration, stop: &AtomicBool) -> Vec<Write> {
    crate::rt::precise_timers();
    let mut writes = Vec::new();
    let mut pacer = Pacer::new(period);
    while !stop.load(Ordering::Acquire) {
        let n = writes.len() as u64;
        let text = batch(ids, n);
        let at = Instant::now();
        if ws.send(Message::text(text)).is_err() {
            break;
        }
        writes.push(Write { n, at });
        pacer.wait();
    }
    let _ = ws.close(None);
    writes
}

#[cfg(test)]
mod tests {
    use super::telemetry::dropped_field;
    use super::*;

    #[test]
    fn batches_encode_the_write_in_exact_degrees() {
        let b = batch(&[1, 2], 3);
        let v: serde_json::Value = serde_json::from_str(&b).expect("json");
        let deg = v["targets"][1]["position_deg"].as_f64().expect("deg");
        assert_eq!((deg * 128.0).round() as i16, angle_of(3));
        assert_eq!(v["targets"].as_array().map(Vec::len), Some(2));
    }

    #[test]
    fn dropped_is_read_from_the_message() {
        assert_eq!(
            dropped_field(r#"{"type":"telemetry","seq":4,"t_ms":1,"dropped":17,"joints":[]}"#),
            17
        );
        assert_eq!(dropped_field(r#"{"type":"telemetry"}"#), 0);
    }
}
