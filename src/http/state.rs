//! What every handler shares: the bus handles by name, the soft limits and
//! the token. Cheap to clone (one `Arc`).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use super::error::ApiResult;
use super::hub::WsHub;
use super::policy::{RefusalLog, RequestPolicy};
use super::request_stats::RequestStats;
use crate::bus::firmware::FirmwareSource;
use crate::bus::handle::DeviceState;
use crate::bus::BusHandle;
use crate::control::limits::SoftLimits;
use crate::control::teleop::WatchdogDefault;
use crate::control::Control;
use crate::protocol::params::Revision;

pub use crate::control::joints::{device_id, known_device};

/// Options of the config file: the control core's, and the HTTP layer's own.
#[derive(Debug, Clone, Default)]
pub struct StateOptions {
    /// The named hands and their saved poses.
    pub hands: Option<Arc<crate::hands::StateStore>>,
    pub web_dir: Option<std::path::PathBuf>,
    /// (bus or every bus, id) → name.
    pub joint_names: BTreeMap<(Option<String>, u8), String>,
    pub watchdog: WatchdogDefault,
    /// Host and origin allow-lists, body limit.
    pub policy: RequestPolicy,
    /// Where recordings are written (`state_dir/recordings`); absent: a
    /// directory under the system's temporary one.
    pub recordings_dir: Option<std::path::PathBuf>,
    /// The ROS 2 bridge's counters, when it runs.
    pub ros2: Option<Arc<crate::control::ros2_stats::Ros2Stats>>,
    /// The devices each bus was configured with (its `ids`): the ones the
    /// daemon manages. A bus absent here, or with no ids (it scans for its
    /// devices), manages every device it knows.
    pub managed: BTreeMap<String, Vec<u8>>,
}

/// The HTTP layer's own options.
#[derive(Debug, Clone, Default)]
struct HttpOptions {
    web_dir: Option<std::path::PathBuf>,
    policy: RequestPolicy,
}

/// What every handler shares: the control core (every bus, limit and job,
/// reached through `Deref`) and what only HTTP needs.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    control: Arc<Control>,
    token: Option<String>,
    started: Instant,
    ws: WsHub,
    requests: RequestStats,
    refusals: RefusalLog,
    options: std::sync::OnceLock<HttpOptions>,
}

impl std::ops::Deref for AppState {
    type Target = Control;

    fn deref(&self) -> &Control {
        &self.inner.control
    }
}

impl AppState {
    /// An empty token counts as none.
    pub fn new(buses: Vec<BusHandle>, limits: SoftLimits, token: Option<String>) -> Self {
        Self {
            inner: Arc::new(Inner {
                control: Arc::new(Control::new(buses, limits)),
                token: token.filter(|t| !t.is_empty()),
                started: Instant::now(),
                ws: WsHub::default(),
                requests: RequestStats::default(),
                refusals: RefusalLog::default(),
                options: std::sync::OnceLock::new(),
            }),
        }
    }

    /// The control core, shared with the jobs it starts.
    pub fn control(&self) -> &Arc<Control> {
        &self.inner.control
    }

    pub fn token(&self) -> Option<&str> {
        self.inner.token.as_deref()
    }

    /// The daemon's options beyond buses, limits and token (set once, at
    /// start; a second call is refused and gets its options back).
    pub fn set_options(&self, options: StateOptions) -> Result<(), Box<StateOptions>> {
        let http = HttpOptions {
            web_dir: options.web_dir.clone(),
            policy: options.policy.clone(),
        };
        let control = crate::control::Options {
            hands: options.hands.clone(),
            joint_names: options.joint_names.clone(),
            watchdog: options.watchdog,
            recordings_dir: options.recordings_dir.clone(),
            ros2: options.ros2.clone(),
            managed: options.managed.clone(),
        };
        if self.inner.control.set_options(control).is_err() || self.inner.options.set(http).is_err()
        {
            return Err(Box::new(options));
        }
        Ok(())
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
    pub(crate) fn requests(&self) -> &RequestStats {
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
    /// The bus handle and the checked device id.
    pub fn resolve<'a>(&self, state: &'a AppState) -> ApiResult<(&'a BusHandle, u8)> {
        let bus = state.bus(&self.bus)?;
        Ok((bus, device_id("id", self.id)?))
    }
}

/// Names the buses; the token must never reach a log line.
impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let buses: Vec<&str> = self.buses().map(BusHandle::name).collect();
        f.debug_struct("AppState")
            .field("buses", &buses)
            .finish_non_exhaustive()
    }
}

/// 422 when device `id` runs a revision older than `need` (saying which and
/// how the daemon knows), 409 while its revision is not known yet. `field`
/// names the request member, `what` the feature asked for.
pub(crate) fn require_revision(
    field: &str,
    what: &str,
    need: Revision,
    id: u8,
    dev: &DeviceState,
) -> ApiResult<()> {
    let need_s = need.as_str();
    match dev.firmware {
        Some(f) if f.revision >= need => Ok(()),
        Some(f) => Err(super::error::ApiError::invalid(
            field,
            format!(
                "{what} needs rev {need_s} firmware; device {id} runs {} ({})",
                f.revision.as_str(),
                match f.source {
                    FirmwareSource::Config => "set in the config",
                    FirmwareSource::Detected => "detected",
                }
            ),
        )),
        None => Err(super::error::ApiError::conflict(
            "firmware-unknown",
            "Firmware revision not known yet",
            format!(
                "{what} needs rev {need_s} firmware and device {id}'s revision is not known yet \
                 (it is asked once the device answers; or set `firmware` in the bus's config)"
            ),
        )
        .with_field(field)),
    }
}
