//! The `jointd` binary run as a daemon: spawned with arguments, its address
//! learnt from the first line it prints (`listening on http://…`), its log
//! (stderr) read line by line as it comes, killed when the test drops it.
//! Each daemon gets a temp dir of its own (`TMPDIR`), removed with it: a
//! killed daemon cannot remove its simulator's pty link or its default
//! recordings dir itself.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_jointd");

/// How long a daemon gets to answer, start, log a line or exit: far more
/// than it needs on an idle host, so only a real failure reaches it.
pub const WAIT: Duration = Duration::from_secs(20);

/// A running `jointd`: its base URL and its log lines.
pub struct Daemon {
    pub child: Child,
    /// `http://127.0.0.1:PORT`, as the daemon printed it.
    pub base: String,
    log: Receiver<String>,
    seen: Vec<String>,
    /// Its `TMPDIR`, when this rig made one.
    tmp: Option<PathBuf>,
}

/// A fresh directory for one daemon's `TMPDIR`.
fn private_tmp() -> PathBuf {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("jointd-test-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temp dir for the daemon");
    dir
}

impl Daemon {
    /// The command [`Daemon::spawn`] runs: `jointd ARGS` without a token
    /// from the environment and without colours in its log. Add to it and
    /// give it to [`Daemon::start`].
    pub fn command(args: &[&str]) -> Command {
        let mut cmd = Command::new(BIN);
        cmd.args(args)
            .env_remove("JOINTD_TOKEN")
            .env("NO_COLOR", "1");
        cmd
    }

    /// Starts `jointd ARGS` (give it `--listen 127.0.0.1:0`) and waits for
    /// its address line.
    pub fn spawn(args: &[&str]) -> Self {
        Self::start(Self::command(args))
    }

    /// Starts `cmd` and waits for its address line; panics with the log
    /// when the daemon exits without one.
    pub fn start(mut cmd: Command) -> Self {
        let given = cmd.get_envs().any(|(k, _)| k == "TMPDIR");
        let tmp = (!given).then(private_tmp);
        if let Some(dir) = &tmp {
            cmd.env("TMPDIR", dir);
        }
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn jointd");
        let (tx, log) = channel();
        let stderr = child.stderr.take().expect("stderr");
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        let _ = stdout.read_line(&mut first);
        // Whatever else it prints is read and dropped, so that a write to
        // stdout never meets a closed pipe.
        std::thread::spawn(move || {
            let _ = stdout.read_to_end(&mut Vec::new());
        });
        let mut daemon = Self {
            child,
            base: String::new(),
            log,
            seen: Vec::new(),
            tmp,
        };
        match first.trim().strip_prefix("listening on ") {
            Some(base) => daemon.base = base.to_owned(),
            None => {
                let _ = daemon.child.kill();
                let _ = daemon.child.wait();
                panic!(
                    "no address line from jointd (got {first:?}); its log:\n{}",
                    daemon.log_to_end()
                );
            }
        }
        daemon
    }

    /// [`Daemon::start`] of `jointd ARGS --listen 127.0.0.1:0` at log level
    /// info, the command adjusted first (environment, resource limits).
    pub fn start_with(args: &[&str], tweak: impl FnOnce(&mut Command)) -> Self {
        let mut cmd = Self::command(args);
        cmd.args(["--listen", "127.0.0.1:0"])
            .env("RUST_LOG", "info");
        tweak(&mut cmd);
        Self::start(cmd)
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// Every log line printed so far (no waiting for more).
    pub fn log(&mut self) -> String {
        while let Ok(line) = self.log.try_recv() {
            self.seen.push(line);
        }
        self.seen.join("\n")
    }

    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(self.child.id() as i32), signal)
            .expect("signal jointd");
    }

    /// Its exit status once it has exited, `None` if it has not `within`.
    pub fn wait_exit(&mut self, within: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + within;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                return Some(status);
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The first log line (seen or to come) holding every one of `parts`.
    pub fn log_line(&mut self, parts: &[&str]) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(line) = self
                .seen
                .iter()
                .find(|l| parts.iter().all(|p| l.contains(p)))
            {
                return line.clone();
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.log.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(_) => panic!(
                    "no log line with {parts:?}; seen:\n{}",
                    self.seen.join("\n")
                ),
            }
        }
    }

    /// Every log line, after the daemon has exited (or been killed): those
    /// already seen and the rest up to the end of its stderr.
    pub fn log_to_end(&mut self) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.log.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => {
                    panic!("jointd's log never ended:\n{}", self.seen.join("\n"))
                }
            }
        }
        self.seen.join("\n")
    }

    /// Stops it as a service manager would (SIGTERM) and waits for its
    /// exit, at most [`WAIT`].
    pub fn stop(&mut self) -> ExitStatus {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM");
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(status) = self.child.try_wait().expect("wait for jointd") {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "jointd did not exit after SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Kills it (SIGKILL: no shutdown of its own) and reaps it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.kill();
        if let Some(dir) = &self.tmp {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// Waits until `n` joints of `sim0` are online.
pub async fn wait_online(client: &reqwest::Client, d: &mut Daemon, n: usize, within: Duration) {
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
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
