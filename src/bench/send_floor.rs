//! The kernel's part of telemetry fan-out, measured apart from the daemon:
//! `clients` loopback TCP connections, a blocking reader thread on each
//! (as the bench's telemetry clients are), and one thread that writes a
//! message of the telemetry's size to every connection at the telemetry
//! rate and does nothing else. Its CPU is what one send per client per tick
//! costs on this host (the system call, TCP, the loopback's receive path
//! run in the sender's context, waking the reader), whatever the daemon
//! builds around it: the floor under the fan-out's cost.

use std::io::{Read, Write as _};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::args::BenchError;
use super::client::Pacer;
use super::cpu;

const SENDER_THREAD: &str = "bench-floor";
const READER_THREAD: &str = "bench-sink";
/// How long a reader's read waits before it checks for stop.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// What the sends alone cost.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SendFloor {
    /// The sender thread's CPU, share of one core.
    pub sender_cpu: f64,
    /// Messages it sent per second (all connections).
    pub sends_per_s: f64,
}

/// Sends `len` bytes to each of `clients` connections `rate_hz` times a
/// second for `seconds`, after `warmup`.
pub(crate) fn measure(
    clients: usize,
    rate_hz: f64,
    len: usize,
    warmup: Duration,
    seconds: Duration,
) -> Result<SendFloor, BenchError> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let addr = listener.local_addr()?;
    let stop = Arc::new(AtomicBool::new(false));
    let mut senders = Vec::with_capacity(clients);
    let mut readers: Vec<JoinHandle<()>> = Vec::with_capacity(clients);
    for _ in 0..clients {
        let reading = TcpStream::connect(addr)?;
        let (sending, _) = listener.accept()?;
        sending.set_nodelay(true)?;
        reading.set_read_timeout(Some(READ_TIMEOUT))?;
        let flag = stop.clone();
        readers.push(
            std::thread::Builder::new()
                .name(READER_THREAD.into())
                .spawn(move || drain(reading, &flag))?,
        );
        senders.push(sending);
    }
    let period = Duration::from_secs_f64(1.0 / rate_hz.max(f64::EPSILON));
    let message = vec![b'x'; len.max(1)];
    let flag = stop.clone();
    let sender = std::thread::Builder::new()
        .name(SENDER_THREAD.into())
        .spawn(move || send_each_tick(&mut senders, &message, period, &flag))?;
    std::thread::sleep(warmup);
    let (t0, c0) = (Instant::now(), cpu::snapshot(&[SENDER_THREAD]));
    std::thread::sleep(seconds);
    let (t1, c1) = (Instant::now(), cpu::snapshot(&[SENDER_THREAD]));
    stop.store(true, Ordering::Release);
    let sent = sender.join().unwrap_or(0);
    for r in readers {
        let _ = r.join();
    }
    let window = t1.duration_since(t0).as_secs_f64().max(f64::EPSILON);
    let used = c1[0].saturating_sub(c0[0]).as_secs_f64();
    let whole = (warmup + seconds).as_secs_f64().max(f64::EPSILON);
    Ok(SendFloor {
        sender_cpu: used / window,
        sends_per_s: sent as f64 / whole,
    })
}

/// Every period, the message to every connection; returns the sends made.
fn send_each_tick(
    conns: &mut [TcpStream],
    message: &[u8],
    period: Duration,
    stop: &AtomicBool,
) -> u64 {
    let mut pacer = Pacer::new(period);
    let mut sent = 0;
    while !stop.load(Ordering::Acquire) {
        for c in conns.iter_mut() {
            if c.write_all(message).is_ok() {
                sent += 1;
            }
        }
        pacer.wait();
    }
    sent
}

fn drain(mut conn: TcpStream, stop: &AtomicBool) {
    let mut buf = vec![0u8; 64 * 1024];
    while !stop.load(Ordering::Acquire) {
        match conn.read(&mut buf) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => break,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sends_reach_every_connection_at_the_rate() {
        let floor = measure(
            4,
            100.0,
            2_000,
            Duration::from_millis(50),
            Duration::from_millis(300),
        )
        .expect("a loopback floor");
        // 4 connections at 100 Hz: 400 a second, less a tick or two lost
        // at the edges or to a busy host.
        assert!(floor.sends_per_s > 200.0, "{floor:?}");
        assert!(floor.sends_per_s <= 600.0, "{floor:?}");
        assert!(floor.sender_cpu > 0.0, "{floor:?}");
    }
}
