//! What every handler shares: the control core and what HTTP alone needs.
//! Cheap to clone (one `Arc`).

use std::sync::Arc;
use std::time::Instant;

use super::error::ApiResult;
use super::hub::WsHub;
use super::policy::{RefusalLog, RequestPolicy};
use super::request_stats::RequestStats;
use super::tokens::Tokens;
use crate::control::bus_reader::BusReader;
use crate::control::Control;

pub use crate::control::joints::{device_id, known_device};

/// What the HTTP layer alone reads of the config file (the core's own
/// options are `control::Options`, set on the core).
#[derive(Debug, Clone, Default)]
pub struct HttpOptions {
    pub web_dir: Option<std::path::PathBuf>,
    /// Host and origin allow-lists, body limit.
    pub policy: RequestPolicy,
}

/// What every handler shares: the control core, which the daemon built and
/// shares with ROS 2, and what only HTTP needs (the token, the WebSocket
/// hub, request counters, its options).
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    control: Arc<Control>,
    tokens: Tokens,
    started: Instant,
    ws: WsHub,
    requests: Arc<RequestStats>,
    refusals: RefusalLog,
    options: std::sync::OnceLock<HttpOptions>,
}

impl AppState {
    /// Serves `control` with one token (`--token`: every scope); an empty
    /// token counts as none.
    pub fn new(control: Arc<Control>, token: Option<String>) -> Self {
        Self::with_tokens(control, Tokens::single(token))
    }

    /// Serves `control` to the holders of `tokens`, each within its scope
    /// (none: the API is open).
    pub fn with_tokens(control: Arc<Control>, tokens: Tokens) -> Self {
        Self {
            inner: Arc::new(Inner {
                control,
                tokens,
                started: Instant::now(),
                ws: WsHub::default(),
                requests: Arc::default(),
                refusals: RefusalLog::default(),
                options: std::sync::OnceLock::new(),
            }),
        }
    }

    /// The control core every handler acts through.
    pub fn control(&self) -> &Arc<Control> {
        &self.inner.control
    }

    /// The tokens requests are checked against.
    pub fn tokens(&self) -> &Tokens {
        &self.inner.tokens
    }

    /// HTTP's options (set once, at start; a second call is refused and
    /// gets its options back).
    pub fn set_options(&self, options: HttpOptions) -> Result<(), Box<HttpOptions>> {
        self.inner.options.set(options).map_err(Box::new)
    }

    fn options(&self) -> &HttpOptions {
        static DEFAULTS: std::sync::OnceLock<HttpOptions> = std::sync::OnceLock::new();
        self.inner
            .options
            .get()
            .unwrap_or_else(|| DEFAULTS.get_or_init(HttpOptions::default))
    }

    /// Serve the dashboard from this folder instead of the embedded copy.
    pub fn web_dir(&self) -> Option<&std::path::PathBuf> {
        self.options().web_dir.as_ref()
    }

    /// Which hosts and origins are served, and the body limit.
    pub fn policy(&self) -> &RequestPolicy {
        &self.options().policy
    }

    /// Which refused hosts/origins were logged.
    pub(crate) fn refusals(&self) -> &RefusalLog {
        &self.inner.refusals
    }

    /// What the WebSocket connections share.
    pub fn ws(&self) -> &WsHub {
        &self.inner.ws
    }

    /// Answered requests by route and status, for `/metrics`.
    pub(crate) fn requests(&self) -> &Arc<RequestStats> {
        &self.inner.requests
    }

    pub fn uptime_s(&self) -> f64 {
        self.inner.started.elapsed().as_secs_f64()
    }
}

/// `{bus}` path parameter.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Path)]
pub struct BusPath {
    /// Bus name as configured (`bus0`, ... for `--bus` / `--sim`).
    #[param(example = "sim0")]
    pub bus: String,
}

/// `{bus}/devices/{id}` path parameters.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Path)]
pub struct DevicePath {
    #[param(example = "sim0")]
    pub bus: String,
    /// Device id, 1..=159, in plain decimal (`+1` and `01` are malformed).
    #[param(minimum = 1, maximum = 159, example = 1)]
    #[serde(deserialize_with = "plain_decimal")]
    pub id: i64,
}

/// A path integer written as a number is written: an optional `-`, then `0`
/// or digits without a leading zero. `+1` or `01` would name device 1 by
/// another URL (caches, logs and allow-rules keyed by path would miss it).
fn plain_decimal<'de, D: serde::Deserializer<'de>>(d: D) -> Result<i64, D::Error> {
    let text = <std::borrow::Cow<'de, str> as serde::Deserialize>::deserialize(d)?;
    let digits = text.strip_prefix('-').unwrap_or(&text);
    let plain = !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && (digits == "0" || !digits.starts_with('0'));
    if !plain {
        return Err(serde::de::Error::custom(format!(
            "`{text}` is not a device id: write it in plain decimal (e.g. 1, not +1 or 01)"
        )));
    }
    text.parse()
        .map_err(|_| serde::de::Error::custom(format!("`{text}` is not a device id: too large")))
}

impl DevicePath {
    /// The bus (read only) and the checked device id: 404 for the bus
    /// first, then 422 for the id.
    pub fn resolve(&self, state: &AppState) -> ApiResult<(BusReader, u8)> {
        let bus = state.control().reader(&self.bus)?;
        Ok((bus, device_id("id", self.id)?))
    }
}

/// Names the buses; the token must never reach a log line.
impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let buses: Vec<String> = self
            .control()
            .readers()
            .map(|b| b.name().to_owned())
            .collect();
        f.debug_struct("AppState")
            .field("buses", &buses)
            .finish_non_exhaustive()
    }
}
