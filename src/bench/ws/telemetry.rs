//! The telemetry clients of the WebSocket bench: each subscribes at the
//! asked rate and counts what it receives, what the daemon says it
//! skipped, and the bytes.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use tungstenite::stream::MaybeTlsStream;
use tungstenite::Message;

use super::socket::{connect, Socket, TELEMETRY_THREAD};
use crate::bench::args::BenchError;

/// Telemetry clients: one thread each, counting telemetry messages and the
/// samples the daemon reports they skipped.
pub(super) struct Telemetry {
    stop: Arc<AtomicBool>,
    counts: Arc<Vec<AtomicU64>>,
    dropped: Arc<AtomicU64>,
    /// Bytes of every telemetry message taken.
    bytes: Arc<AtomicU64>,
    joins: Vec<JoinHandle<()>>,
}

/// How long a telemetry client's read waits before it checks for stop.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

impl Telemetry {
    pub(super) fn start(url: &str, n: usize, rate_hz: f64) -> Result<Telemetry, BenchError> {
        let stop = Arc::new(AtomicBool::new(false));
        let counts = Arc::new((0..n).map(|_| AtomicU64::new(0)).collect::<Vec<_>>());
        let dropped = Arc::new(AtomicU64::new(0));
        let bytes = Arc::new(AtomicU64::new(0));
        let mut joins = Vec::with_capacity(n);
        for i in 0..n {
            let mut ws = connect(url)?;
            if let MaybeTlsStream::Plain(s) = ws.get_ref() {
                s.set_read_timeout(Some(READ_TIMEOUT))?;
            }
            let sub = format!(r#"{{"type":"subscribe","rate_hz":{rate_hz}}}"#);
            ws.send(Message::text(sub))
                .map_err(|e| BenchError::Setup(format!("subscribe: {e}")))?;
            let (stop, counts) = (stop.clone(), counts.clone());
            let (dropped, bytes) = (dropped.clone(), bytes.clone());
            joins.push(
                std::thread::Builder::new()
                    .name(TELEMETRY_THREAD.into())
                    .spawn(move || watch(ws, &counts[i], &dropped, &bytes, &stop))?,
            );
        }
        Ok(Telemetry {
            stop,
            counts,
            dropped,
            bytes,
            joins,
        })
    }

    pub(super) fn counts(&self) -> Vec<u64> {
        self.counts
            .iter()
            .map(|c| c.load(Ordering::Relaxed))
            .collect()
    }

    /// Per-client messages/s since `from` over `elapsed`: (min, mean), and skipped samples.
    pub(super) fn rates(&self, from: &[u64], elapsed: Duration) -> Option<(f64, f64, u64)> {
        if from.is_empty() {
            return None;
        }
        let secs = elapsed.as_secs_f64().max(f64::EPSILON);
        let rates: Vec<f64> = self
            .counts()
            .iter()
            .zip(from)
            .map(|(b, a)| (b - a) as f64 / secs)
            .collect();
        let min = rates.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = rates.iter().sum::<f64>() / rates.len() as f64;
        Some((min, mean, self.dropped.load(Ordering::Relaxed)))
    }

    /// Mean size of the telemetry messages taken, bytes (none taken: `None`).
    pub(super) fn mean_len(&self) -> Option<f64> {
        let n: u64 = self.counts().iter().sum();
        (n > 0).then(|| self.bytes.load(Ordering::Relaxed) as f64 / n as f64)
    }

    pub(super) fn stop(self) {
        self.stop.store(true, Ordering::Release);
        for j in self.joins {
            let _ = j.join();
        }
    }
}

fn watch(
    mut ws: Socket,
    count: &AtomicU64,
    dropped: &AtomicU64,
    bytes: &AtomicU64,
    stop: &AtomicBool,
) {
    while !stop.load(Ordering::Acquire) {
        match ws.read() {
            Ok(Message::Text(t)) if t.as_str().starts_with(r#"{"type":"telemetry""#) => {
                count.fetch_add(1, Ordering::Relaxed);
                bytes.fetch_add(t.len() as u64, Ordering::Relaxed);
                dropped.fetch_add(dropped_field(t.as_str()), Ordering::Relaxed);
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => break,
        }
    }
    let _ = ws.close(None);
}

/// The `dropped` count of a telemetry message, without parsing all of it.
pub(super) fn dropped_field(text: &str) -> u64 {
    text.split_once(r#""dropped":"#)
        .map(|(_, rest)| {
            rest.chars()
                .take_while(char::is_ascii_digit)
                .collect::<String>()
        })
        .and_then(|d| d.parse().ok())
        .unwrap_or(0)
}
