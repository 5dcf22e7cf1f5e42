//! `jointd record --out run.mcap [--duration S] [--url URL]`: asks a
//! running daemon for a recording (`POST /api/v1/recordings`), waits for
//! its duration or Ctrl-C (then `DELETE`, which completes the file), and
//! downloads it (`GET .../file`) to `--out`, written beside it and renamed
//! into place. Plain HTTP/1.1 over TCP: the daemon serves no TLS itself.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use serde_json::{json, Value};
use thiserror::Error;

/// Arguments of `jointd record`.
#[derive(Args, Debug, Clone)]
pub struct RecordArgs {
    /// Where to write the MCAP file.
    #[arg(long)]
    pub out: PathBuf,
    /// Stop after this many seconds (default: at Ctrl-C).
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// The daemon's base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    pub url: String,
    /// Frames, events and setpoints as `std_msgs/msg/String` (CDR) instead
    /// of JSON: one serialization for every channel, as `ros2 bag play` asks.
    #[arg(long)]
    pub bag_compatible: bool,
    /// Bearer token, if the daemon asks for one.
    #[arg(long, env = "JOINTD_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

#[derive(Debug, Error)]
pub enum RecordCliError {
    #[error("--url {0}: only http://HOST:PORT[/PATH] is understood")]
    Url(String),
    #[error("--duration {0}: give a number of seconds above 0")]
    Duration(f64),
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    #[error("{what}: the daemon answered {status}: {body}")]
    Status {
        what: String,
        status: u16,
        body: String,
    },
    #[error("{0}: the daemon's answer is not HTTP/1.1 as expected")]
    Malformed(String),
    #[error("signals: {0}")]
    Signals(String),
}

/// How often the recording's state is asked while waiting.
const POLL: Duration = Duration::from_millis(200);
/// A response bigger than this is refused (a recording of hours at most).
const MAX_BODY: usize = 4 << 30;

/// Runs `jointd record`; the final status of the recording.
pub fn run(args: &RecordArgs) -> Result<Value, RecordCliError> {
    if args.duration.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
        return Err(RecordCliError::Duration(args.duration.unwrap_or(0.0)));
    }
    let api = Api::new(&args.url, args.token.clone())?;
    let interrupted = watch_signals()?;
    let mut body = json!({"bag_compatible": args.bag_compatible});
    if let Some(s) = args.duration {
        body["duration_s"] = json!(s);
    }
    let started = api.call("POST", "/api/v1/recordings", Some(&body), "starting")?;
    let id = started["id"].as_u64().unwrap_or(0);
    eprintln!(
        "jointd record: recording {id} started{}",
        match args.duration {
            Some(s) => format!(" for {s} s (Ctrl-C stops it sooner)"),
            None => " (Ctrl-C stops it)".into(),
        }
    );
    let path = format!("/api/v1/recordings/{id}");
    loop {
        if interrupted.load(Ordering::SeqCst) {
            api.call("DELETE", &path, None, "stopping")?;
            break;
        }
        let status = api.call("GET", &path, None, "reading its state")?;
        if status["state"] != "recording" {
            break;
        }
        std::thread::sleep(POLL);
    }
    let final_status = api.call("GET", &path, None, "reading its state")?;
    let bytes = api.get_bytes(&format!("{path}/file"), "downloading")?;
    let tmp = args.out.with_extension("mcap.part");
    std::fs::write(&tmp, &bytes)
        .and_then(|()| std::fs::rename(&tmp, &args.out))
        .map_err(|e| RecordCliError::Io(args.out.display().to_string(), e))?;
    eprintln!(
        "jointd record: {} bytes written to {}",
        bytes.len(),
        args.out.display()
    );
    Ok(final_status)
}

/// SIGINT/SIGTERM set the flag instead of ending the process, so the
/// recording is stopped and downloaded.
fn watch_signals() -> Result<Arc<AtomicBool>, RecordCliError> {
    use nix::sys::signal::{SigSet, Signal};
    let mut signals = SigSet::empty();
    signals.add(Signal::SIGINT);
    signals.add(Signal::SIGTERM);
    signals
        .thread_block()
        .map_err(|e| RecordCliError::Signals(e.to_string()))?;
    let flag = Arc::new(AtomicBool::new(false));
    let set = flag.clone();
    std::thread::spawn(move || {
        if signals.wait().is_ok() {
            set.store(true, Ordering::SeqCst);
        }
    });
    Ok(flag)
}

/// The daemon at one address.
struct Api {
    authority: String,
    prefix: String,
    token: Option<String>,
}

impl Api {
    fn new(url: &str, token: Option<String>) -> Result<Self, RecordCliError> {
        let rest = url
            .strip_prefix("http://")
            .ok_or_else(|| RecordCliError::Url(url.into()))?;
        let (authority, prefix) = match rest.find('/') {
            Some(i) => (&rest[..i], rest[i..].trim_end_matches('/')),
            None => (rest, ""),
        };
        if authority.is_empty() {
            return Err(RecordCliError::Url(url.into()));
        }
        Ok(Self {
            authority: authority.to_owned(),
            prefix: prefix.to_owned(),
            token: token.filter(|t| !t.is_empty()),
        })
    }

    fn call(
        &self,
        method: &str,
        path: &str,
        body: Option<&Value>,
        what: &str,
    ) -> Result<Value, RecordCliError> {
        let bytes = self.request(method, path, body, what)?;
        serde_json::from_slice(&bytes).map_err(|_| RecordCliError::Malformed(what.into()))
    }

    fn get_bytes(&self, path: &str, what: &str) -> Result<Vec<u8>, RecordCliError> {
        self.request("GET", path, None, what)
    }

    fn request(
        &self,
        method: &str,
        path: &str,
        body: Option<&Value>,
        what: &str,
    ) -> Result<Vec<u8>, RecordCliError> {
        let io = |e| RecordCliError::Io(format!("{what} ({})", self.authority), e);
        let mut stream = TcpStream::connect(&self.authority).map_err(io)?;
        let body = body.map(Value::to_string).unwrap_or_default();
        let mut head = format!(
            "{method} {}{path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nAccept: */*\r\n",
            self.prefix, self.authority
        );
        if let Some(t) = &self.token {
            head.push_str(&format!("Authorization: Bearer {t}\r\n"));
        }
        if !body.is_empty() {
            head.push_str(&format!(
                "Content-Type: application/json\r\nContent-Length: {}\r\n",
                body.len()
            ));
        }
        head.push_str("\r\n");
        stream.write_all(head.as_bytes()).map_err(io)?;
        stream.write_all(body.as_bytes()).map_err(io)?;
        let mut raw = Vec::new();
        stream
            .take(MAX_BODY as u64)
            .read_to_end(&mut raw)
            .map_err(io)?;
        let (status, chunked, body) =
            split_response(&raw).ok_or_else(|| RecordCliError::Malformed(what.into()))?;
        let body = if chunked {
            dechunk(body).ok_or_else(|| RecordCliError::Malformed(what.into()))?
        } else {
            body.to_vec()
        };
        if !(200..300).contains(&status) {
            return Err(RecordCliError::Status {
                what: what.into(),
                status,
                body: String::from_utf8_lossy(&body).chars().take(500).collect(),
            });
        }
        Ok(body)
    }
}

/// Status, whether the body is chunked, and the body.
fn split_response(raw: &[u8]) -> Option<(u16, bool, &[u8])> {
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&raw[..end]).ok()?;
    let mut lines = head.split("\r\n");
    let status = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let chunked = lines.any(|l| {
        let l = l.to_ascii_lowercase();
        l.starts_with("transfer-encoding:") && l.contains("chunked")
    });
    Some((status, chunked, &raw[end + 4..]))
}

/// A chunked body joined.
fn dechunk(mut body: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let eol = body.windows(2).position(|w| w == b"\r\n")?;
        let size_text = std::str::from_utf8(&body[..eol]).ok()?;
        let size = usize::from_str_radix(size_text.split(';').next()?.trim(), 16).ok()?;
        body = &body[eol + 2..];
        if size == 0 {
            return Some(out);
        }
        out.extend_from_slice(body.get(..size)?);
        body = body.get(size + 2..)?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn responses_are_split_and_chunked_bodies_joined() {
        let raw = b"HTTP/1.1 201 Created\r\ncontent-type: x\r\n\r\n{\"id\":1}";
        let (status, chunked, body) = split_response(raw).unwrap();
        assert_eq!((status, chunked, body), (201, false, &b"{\"id\":1}"[..]));
        let raw = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\n";
        let (_, chunked, body) = split_response(raw).unwrap();
        assert!(chunked);
        assert_eq!(dechunk(body).unwrap(), b"abcde");
        assert!(dechunk(b"5\r\nab").is_none(), "a cut body is not a body");
    }

    #[test]
    fn only_plain_http_urls_are_taken() {
        let api = Api::new("http://10.0.0.2:8080/jointd/", None).unwrap();
        assert_eq!(
            (api.authority.as_str(), api.prefix.as_str()),
            ("10.0.0.2:8080", "/jointd")
        );
        assert!(Api::new("https://x", None).is_err());
        assert!(Api::new("http:///x", None).is_err());
    }
}
