//! A minimal host for simulator tests: the protocol module on one end of a
//! pty or memory line, with waits that poll an event up to a deadline.
#![allow(dead_code)]

use std::time::{Duration, Instant};

use jointd::protocol::{
    Command, Config, ConfigParam, Info01, InfoBlock, Message, Reply, ReplyBody, StreamDecoder,
};
use jointd::sim::{SimConfig, SimHandle, Simulator};
use jointd::transport::tty::TtyPort;
use jointd::transport::Transport;

/// Generous: the machine is loaded, and these waits end on the event.
pub const WAIT: Duration = Duration::from_secs(5);
pub const BAUD: u32 = 500_000;

pub struct Host {
    pub port: Box<dyn Transport>,
    pub decoder: StreamDecoder,
}

pub fn config(ids: &[u8]) -> SimConfig {
    let mut cfg = SimConfig::new(ids.to_vec(), BAUD);
    cfg.align_time = Duration::from_millis(50);
    cfg.boot_delay = Duration::from_millis(2);
    cfg
}

/// A simulator on a pty and a host that opened it like a USB adapter.
pub fn pty(cfg: SimConfig) -> (SimHandle, Host) {
    let baud = cfg.baud;
    let sim = Simulator::spawn_pty(cfg).expect("spawn pty simulator");
    let path = sim.device_path().expect("pty path");
    let (port, _notes) = TtyPort::open(&path, baud).expect("open simulated tty");
    (
        sim,
        Host {
            port: Box::new(port),
            decoder: StreamDecoder::new(),
        },
    )
}

pub fn memory(cfg: SimConfig) -> (SimHandle, Host) {
    let (sim, port) = Simulator::spawn_memory(cfg).expect("spawn memory simulator");
    (
        sim,
        Host {
            port: Box::new(port),
            decoder: StreamDecoder::new(),
        },
    )
}

impl Host {
    pub fn send(&mut self, cmd: Command) {
        self.port.write_all(&cmd.encode()).expect("write frame");
    }

    pub fn send_many(&mut self, cmds: &[Command]) {
        let bytes: Vec<u8> = cmds.iter().flat_map(|c| c.encode()).collect();
        self.port.write_all(&bytes).expect("write frames");
    }

    /// The next reply frame, or `None` once `timeout` passes.
    pub fn recv(&mut self, timeout: Duration) -> Option<Reply> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 256];
        loop {
            while let Some(frame) = self.decoder.next_frame() {
                if let Ok(Message::Reply(r)) = Message::from_frame(&frame) {
                    return Some(r);
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            let n = self.port.read_timeout(&mut buf, left).expect("read");
            self.decoder.push(&buf[..n]);
        }
    }

    /// Reads everything that arrives within `timeout` (raw bytes).
    pub fn drain(&mut self, timeout: Duration) -> Vec<u8> {
        let deadline = Instant::now() + timeout;
        let mut out = Vec::new();
        let mut buf = [0u8; 256];
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.port.read_timeout(&mut buf, left) {
                Ok(0) | Err(_) => break,
                Ok(n) => out.extend_from_slice(&buf[..n]),
            }
        }
        out
    }

    /// Reads block `block` of `dev_id`; `None` if no reply comes.
    pub fn read(&mut self, dev_id: u8, block: InfoBlock) -> Option<Reply> {
        self.send(Command::Config(Config::read(dev_id, block)));
        let r = self.recv(Duration::from_millis(500))?;
        Some(r)
    }
}

/// Polls `f` until it returns `Some`, or panics after `WAIT`.
pub fn wait_for<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + WAIT;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::yield_now();
    }
}

/// Writes one parameter (no reply expected).
pub fn write(host: &mut Host, dev_id: u8, param: ConfigParam) {
    host.send(Command::Config(Config { dev_id, param }));
}

/// Reads device `id`'s INFO_01, if it answers one.
pub fn info01(host: &mut Host, id: u8) -> Option<Info01> {
    match host.read(id, InfoBlock::Info01)?.body() {
        ReplyBody::Info01(i) => Some(i),
        _ => None,
    }
}
