//! A `jointd` process for a test: started with `--sim`, its address read
//! from the first line it prints, its log (stderr) gathered as it comes,
//! stopped by a signal with its exit awaited. Test files take it with
//! `#[path = "support/daemon.rs"] mod daemon;`.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_jointd");
/// How often a wait looks again at what it waits for.
const POLL: Duration = Duration::from_millis(20);

pub struct Daemon {
    child: Child,
    pub base: String,
    log: Arc<Mutex<String>>,
    reader: Option<JoinHandle<()>>,
}

impl Daemon {
    /// `jointd ARGS --listen 127.0.0.1:0`, and `tweak` on the command first.
    pub fn start(args: &[&str], tweak: impl FnOnce(&mut Command)) -> Self {
        let mut cmd = Command::new(BIN);
        cmd.args(args)
            .args(["--listen", "127.0.0.1:0"])
            .env_remove("JOINTD_TOKEN")
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        tweak(&mut cmd);
        let mut child = cmd.spawn().expect("spawn jointd");
        let log = Arc::new(Mutex::new(String::new()));
        let mut stderr = child.stderr.take().expect("stderr");
        let gathered = log.clone();
        let reader = std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = stderr.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                gathered.lock().unwrap().push_str(&text);
            }
        });
        let mut first = String::new();
        let stdout = child.stdout.take().expect("stdout");
        BufReader::new(stdout)
            .read_line(&mut first)
            .expect("first line");
        let base = match first.trim().strip_prefix("listening on ") {
            Some(base) => base.to_owned(),
            None => {
                let _ = child.kill();
                let _ = child.wait();
                let _ = reader.join();
                panic!("jointd did not start: {first:?}\n{}", log.lock().unwrap());
            }
        };
        Self {
            child,
            base,
            log,
            reader: Some(reader),
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// The log so far.
    pub fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(self.child.id() as i32), signal)
            .expect("signal jointd");
    }

    /// Its exit status once it has exited, `None` if it has not `within`;
    /// the whole log is gathered by then.
    pub fn wait_exit(&mut self, within: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + within;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                if let Some(reader) = self.reader.take() {
                    let _ = reader.join();
                }
                return Some(status);
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(POLL);
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Waits until `n` joints of `sim0` are online.
pub async fn wait_online(client: &reqwest::Client, d: &Daemon, n: usize, within: Duration) {
    let deadline = Instant::now() + within;
    loop {
        let online = match client.get(d.url("/api/v1/buses/sim0/devices")).send().await {
            Ok(r) => r.json::<serde_json::Value>().await.ok().map_or(0, |v| {
                v["devices"]
                    .as_array()
                    .map_or(0, |d| d.iter().filter(|d| d["online"] == true).count())
            }),
            Err(_) => 0,
        };
        if online >= n {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "joints never came online ({online} of {n})\n{}",
            d.log()
        );
        tokio::time::sleep(POLL).await;
    }
}
