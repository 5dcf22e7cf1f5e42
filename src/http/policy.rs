//! Who may talk to the daemon from a browser, decided as pure functions of
//! header values (the middleware in `guard` does the I/O). Two attacks are
//! in view, both from a web page the user happens to visit:
//!
//! - **DNS rebinding**: `evil.example` resolves to 127.0.0.1, so its page
//!   reads and writes the API as if it were same-origin. The browser still
//!   sends `Host: evil.example…`, so every request whose `Host` does not name
//!   the daemon is refused ([`check_host`]), reads included.
//! - **Cross-site requests**: a foreign page may send "simple" POSTs (no
//!   CORS preflight) or open a WebSocket; the browser runs them and only
//!   hides the answer. Every request that changes something, and the
//!   WebSocket upgrade, must come from no browser at all (no `Origin`), from
//!   the daemon's own origin, or from a configured one ([`check_origin`]).

use std::collections::HashSet;
use std::net::{IpAddr, SocketAddr};
use std::sync::Mutex;

use axum::http::Method;

use super::error::ApiError;

/// Default largest request body, bytes.
pub const DEFAULT_MAX_BODY_BYTES: usize = 1024 * 1024;
/// `allowed_hosts` entry that turns the Host check off.
pub const ANY_HOST: &str = "*";
/// Distinct refused hosts/origins logged at WARN; later ones at DEBUG, so
/// a page that loops cannot flood the log.
const MAX_LOGGED: usize = 64;

/// The allow-lists and the body limit, from the config file and flags.
#[derive(Debug, Clone)]
pub struct RequestPolicy {
    /// The address the daemon listens on: its IP is an accepted `Host`.
    pub listen: Option<SocketAddr>,
    /// Extra `Host` names or IPs (any port), lowercase; `*` accepts any.
    pub allowed_hosts: Vec<String>,
    /// Extra browser origins (`scheme://host[:port]`), lowercase.
    pub allowed_origins: Vec<String>,
    pub max_body_bytes: usize,
}

impl Default for RequestPolicy {
    fn default() -> Self {
        Self {
            listen: None,
            allowed_hosts: Vec::new(),
            allowed_origins: Vec::new(),
            max_body_bytes: DEFAULT_MAX_BODY_BYTES,
        }
    }
}

/// What is wrong with an `allowed_hosts` / `allowed_origins` entry.
pub type EntryError = String;

impl RequestPolicy {
    /// Checks and normalises the configured entries (lowercase, no trailing `/`).
    pub fn new(
        listen: Option<SocketAddr>,
        hosts: &[String],
        origins: &[String],
        max_body_bytes: usize,
    ) -> Result<Self, EntryError> {
        if max_body_bytes == 0 {
            return Err("max_body_bytes = 0: no request could carry a body".into());
        }
        let allowed_hosts = hosts
            .iter()
            .map(|h| normal_host_entry(h))
            .collect::<Result<_, _>>()?;
        let allowed_origins = origins
            .iter()
            .map(|o| normal_origin_entry(o))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            listen,
            allowed_hosts,
            allowed_origins,
            max_body_bytes,
        })
    }
}

fn normal_host_entry(entry: &str) -> Result<String, EntryError> {
    let e = entry.trim().to_ascii_lowercase();
    let e = e.trim_end_matches('.');
    if e == ANY_HOST {
        return Ok(e.to_owned());
    }
    let bare = e.trim_start_matches('[').trim_end_matches(']');
    let plain = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '.' | ':');
    if bare.is_empty()
        || !bare.chars().all(plain)
        || (bare.contains(':') && bare.parse::<IpAddr>().is_err())
    {
        return Err(format!(
            "allowed_hosts entry `{entry}`: give a host name or an IP address, without scheme or port"
        ));
    }
    Ok(bare.to_owned())
}

fn normal_origin_entry(entry: &str) -> Result<String, EntryError> {
    let e = entry.trim().trim_end_matches('/').to_ascii_lowercase();
    let authority = e
        .strip_prefix("http://")
        .or_else(|| e.strip_prefix("https://"));
    match authority {
        Some(a) if !a.is_empty() && !a.contains(['/', '?', '#', '@', '*']) => Ok(e),
        _ => Err(format!(
            "allowed_origins entry `{entry}`: give scheme://host[:port], e.g. http://robot-pc:3000"
        )),
    }
}

/// The host part of a `Host` value: lowercase, without port, brackets or
/// trailing dot; `None` if it is not a host.
fn host_name(host: &str) -> Option<String> {
    let host = host.trim().to_ascii_lowercase();
    let name = if let Some(rest) = host.strip_prefix('[') {
        let (v6, after) = rest.split_once(']')?;
        (after.is_empty() || after.starts_with(':')).then_some(v6)?
    } else {
        match host.rsplit_once(':') {
            Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
            Some(_) => return None,
            None => host.as_str(),
        }
    };
    let name = name.trim_end_matches('.');
    (!name.is_empty()).then(|| name.to_owned())
}

/// Whether a `Host` value names this daemon: a loopback name or IP (any
/// port: a container's port mapping or a local proxy changes it, and a
/// rebinding page cannot send a loopback name), the listen IP, or an
/// `allowed_hosts` entry. `None` (no `Host`: not a browser) is accepted.
pub(crate) fn check_host(policy: &RequestPolicy, host: Option<&str>) -> Result<(), ApiError> {
    let Some(raw) = host else { return Ok(()) };
    if policy.allowed_hosts.iter().any(|h| h == ANY_HOST) {
        return Ok(());
    }
    let Some(name) = host_name(raw) else {
        return Err(ApiError::misdirected(raw, "it is not a host name"));
    };
    let ip = name.parse::<IpAddr>().ok();
    let loopback = name == "localhost" || ip.is_some_and(|ip| ip.is_loopback());
    let listen_ip = ip.is_some() && ip == policy.listen.map(|l| l.ip());
    if loopback || listen_ip || policy.allowed_hosts.contains(&name) {
        return Ok(());
    }
    Err(ApiError::misdirected(
        raw,
        "add it to allowed_hosts (--allowed-host) if the daemon is reached by that name",
    ))
}

/// Requests that must pass [`check_origin`]: every method that may change
/// something, and the WebSocket endpoint (its GET upgrade opens a channel
/// that can move joints).
pub(crate) fn changes_state(method: &Method, is_websocket: bool) -> bool {
    is_websocket || !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
}

/// The browser headers of one request.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BrowserHeaders<'a> {
    pub host: Option<&'a str>,
    pub origin: Option<&'a str>,
    pub fetch_site: Option<&'a str>,
}

/// Whether a request that changes something may come from where the
/// browser says it comes from.
///
/// - An `Origin` in `allowed_origins` passes (whatever `Sec-Fetch-Site` says:
///   such a dashboard is another site by design).
/// - Otherwise `Sec-Fetch-Site: cross-site` or `same-site` is refused.
///   Same-site is refused too: another port on the same host (any local dev
///   server, any local web app) is another origin, and the daemon trusts no
///   origin but its own.
/// - An `Origin` equal to the daemon's own (`http(s)://` + `Host`) passes;
///   any other, `null` included (sandboxed frames, `file://`), is refused.
/// - No `Origin` and no cross-site signal: not a browser (curl, scripts), or
///   a same-origin navigation: passes.
pub(crate) fn check_origin(policy: &RequestPolicy, h: BrowserHeaders<'_>) -> Result<(), ApiError> {
    let origin = h
        .origin
        .map(|o| o.trim().trim_end_matches('/').to_ascii_lowercase());
    if let Some(o) = &origin {
        if policy.allowed_origins.contains(o) {
            return Ok(());
        }
    }
    let fetch_site = h.fetch_site.map(|s| s.trim().to_ascii_lowercase());
    if let Some(site @ ("cross-site" | "same-site")) = fetch_site.as_deref() {
        let from = origin.as_deref().unwrap_or("a page of another site");
        return Err(ApiError::foreign_origin(
            from,
            &format!("Sec-Fetch-Site: {site}"),
        ));
    }
    match origin {
        None => Ok(()),
        Some(o) if is_own_origin(&o, h.host) => Ok(()),
        Some(o) => Err(ApiError::foreign_origin(&o, "Origin")),
    }
}

/// `http://` or `https://` (behind a TLS proxy) followed by the `Host`.
fn is_own_origin(origin: &str, host: Option<&str>) -> bool {
    let Some(host) = host else { return false };
    let authority = origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"));
    authority.is_some_and(|a| a.eq_ignore_ascii_case(host.trim()))
}

/// Remembers which refused hosts/origins were logged, so each is a WARN
/// once (up to [`MAX_LOGGED`] distinct ones).
#[derive(Debug, Default)]
pub(crate) struct RefusalLog {
    // std Mutex: held for one set lookup, never across an await.
    seen: Mutex<HashSet<String>>,
}

impl RefusalLog {
    /// True the first time `key` is refused.
    pub(crate) fn first_time(&self, key: &str) -> bool {
        let Ok(mut seen) = self.seen.lock() else {
            return false;
        };
        if seen.len() >= MAX_LOGGED || seen.contains(key) {
            return false;
        }
        seen.insert(key.to_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(hosts: &[&str], origins: &[&str]) -> RequestPolicy {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        RequestPolicy::new(
            Some("192.168.1.5:8080".parse().unwrap()),
            &s(hosts),
            &s(origins),
            DEFAULT_MAX_BODY_BYTES,
        )
        .unwrap()
    }

    #[test]
    fn host_names_are_parsed() {
        assert_eq!(host_name("LocalHost:8080").as_deref(), Some("localhost"));
        assert_eq!(host_name("[::1]:80").as_deref(), Some("::1"));
        assert_eq!(host_name("[::1]").as_deref(), Some("::1"));
        assert_eq!(host_name("robot.lan.").as_deref(), Some("robot.lan"));
        assert_eq!(host_name("a:b"), None);
        assert_eq!(host_name(""), None);
    }

    #[test]
    fn loopback_listen_ip_and_allowed_hosts_pass() {
        let p = policy(&["Robot-PC"], &[]);
        for ok in [
            "localhost",
            "localhost:1",
            "127.0.0.1:8080",
            "127.1.2.3",
            "[::1]:8080",
        ] {
            assert!(check_host(&p, Some(ok)).is_ok(), "{ok}");
        }
        assert!(check_host(&p, Some("192.168.1.5:8080")).is_ok());
        assert!(check_host(&p, Some("robot-pc:8080")).is_ok());
        assert!(check_host(&p, None).is_ok());
        for bad in [
            "evil.example:8080",
            "localhost.evil.example",
            "192.168.1.6:8080",
            "[::2]",
        ] {
            assert_eq!(
                check_host(&p, Some(bad)).unwrap_err().status().as_u16(),
                421,
                "{bad}"
            );
        }
        assert!(check_host(&policy(&["*"], &[]), Some("evil.example")).is_ok());
    }

    #[test]
    fn origins() {
        let p = policy(&[], &["http://robot-pc:3000/"]);
        let h = |origin, fetch_site| BrowserHeaders {
            host: Some("127.0.0.1:8080"),
            origin,
            fetch_site,
        };
        assert!(check_origin(&p, h(None, None)).is_ok());
        assert!(check_origin(&p, h(Some("http://127.0.0.1:8080"), Some("same-origin"))).is_ok());
        assert!(check_origin(&p, h(None, Some("none"))).is_ok());
        assert!(check_origin(&p, h(Some("http://robot-pc:3000"), Some("cross-site"))).is_ok());
        for (o, s) in [
            (Some("http://evil.example"), None),
            (Some("null"), None),
            (Some("http://127.0.0.1:3000"), Some("same-site")),
            (None, Some("cross-site")),
            (None, Some("same-site")),
            (Some("http://127.0.0.1:8080"), Some("cross-site")),
        ] {
            let err = check_origin(&p, h(o, s)).unwrap_err();
            assert_eq!(err.status().as_u16(), 403, "{o:?} {s:?}");
        }
    }

    #[test]
    fn bad_entries_are_refused() {
        let none: &[String] = &[];
        let one = |s: &str| vec![s.to_owned()];
        assert!(RequestPolicy::new(None, &one("http://x"), none, 1).is_err());
        assert!(RequestPolicy::new(None, &one(""), none, 1).is_err());
        assert!(RequestPolicy::new(None, none, &one("robot-pc:3000"), 1).is_err());
        assert!(RequestPolicy::new(None, none, &one("*"), 1).is_err());
        assert!(RequestPolicy::new(None, none, none, 0).is_err());
        assert!(RequestPolicy::new(None, &one("[fe80::1]"), &one("https://a.b"), 1).is_ok());
    }

    #[test]
    fn refusals_are_logged_once() {
        let log = RefusalLog::default();
        assert!(log.first_time("a"));
        assert!(!log.first_time("a"));
    }
}
