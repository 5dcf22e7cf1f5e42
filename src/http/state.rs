//! What every handler shares: the bus handles by name, the soft limits and
//! the token. Cheap to clone (one `Arc`).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use super::error::{ApiError, ApiResult};
use super::hub::WsHub;
use super::limits::{JointLimits, SoftLimits};
use super::policy::{RefusalLog, RequestPolicy};
use super::teleop::WatchdogDefault;
use crate::bus::firmware::FirmwareSource;
use crate::bus::handle::DeviceState;
use crate::bus::handle::LinkState;
use crate::bus::{BusError, BusHandle, BusSnapshot};
use crate::protocol::params::Revision;
use crate::protocol::{is_device_id, MAX_DEVICE_ID, MIN_DEVICE_ID};

/// Options of the config file that handlers read.
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
    pub ros2: Option<Arc<crate::http::ros2_stats::Ros2Stats>>,
    /// The devices each bus was configured with (its `ids`): the ones the
    /// daemon manages. A bus absent here, or with no ids (it scans for its
    /// devices), manages every device it knows.
    pub managed: BTreeMap<String, Vec<u8>>,
}

#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    buses: BTreeMap<String, BusHandle>,
    limits: SoftLimits,
    token: Option<String>,
    started: Instant,
    ws: WsHub,
    refusals: RefusalLog,
    options: std::sync::OnceLock<StateOptions>,
    moves: crate::http::move_book::MoveBook,
    homings: crate::http::homing_book::HomingBook,
    recordings: crate::http::recording_book::RecordingBook,
}

impl AppState {
    /// An empty token counts as none.
    pub fn new(buses: Vec<BusHandle>, limits: SoftLimits, token: Option<String>) -> Self {
        let buses = buses
            .into_iter()
            .map(|h| (h.name().to_owned(), h))
            .collect();
        Self {
            inner: Arc::new(Inner {
                buses,
                limits,
                token: token.filter(|t| !t.is_empty()),
                started: Instant::now(),
                ws: WsHub::default(),
                refusals: RefusalLog::default(),
                options: std::sync::OnceLock::new(),
                moves: Default::default(),
                homings: Default::default(),
                recordings: Default::default(),
            }),
        }
    }

    pub fn buses(&self) -> impl Iterator<Item = &BusHandle> {
        self.inner.buses.values()
    }

    pub fn bus(&self, name: &str) -> ApiResult<&BusHandle> {
        self.inner
            .buses
            .get(name)
            .ok_or_else(|| ApiError::unknown_bus(name))
    }

    pub fn token(&self) -> Option<&str> {
        self.inner.token.as_deref()
    }

    /// The named hands and their poses (none configured: an empty store).
    pub(crate) fn hands(&self) -> Option<&crate::hands::StateStore> {
        self.options().hands.as_deref()
    }

    /// The moves started through the API.
    pub(crate) fn moves(&self) -> &crate::http::move_book::MoveBook {
        &self.inner.moves
    }

    /// The homing jobs started through the API.
    pub(crate) fn homings(&self) -> &crate::http::homing_book::HomingBook {
        &self.inner.homings
    }

    /// The recordings started through the API.
    pub(crate) fn recordings(&self) -> &crate::http::recording_book::RecordingBook {
        &self.inner.recordings
    }

    /// Names and calibrations of the joints as every edge gives them (REST,
    /// recordings, ROS 2): a hand's joint name, else the configured name,
    /// else `<bus>_<id>`.
    pub(crate) fn joint_labeler(&self) -> crate::record::joint_states::Labeler {
        let state = self.clone();
        Arc::new(move |bus: &str, id: u8| {
            let hand_name = state.hands().and_then(|store| {
                store
                    .hands()
                    .iter()
                    .flat_map(|h| h.joints.iter())
                    .find(|j| j.bus == bus && j.id == id)
                    .map(|j| j.name.clone())
            });
            let name = hand_name
                .or_else(|| state.joint_name(bus, id).map(str::to_owned))
                .unwrap_or_else(|| format!("{bus}_{id}"));
            (name, state.calibration(bus, id))
        })
    }

    /// The ROS 2 bridge's counters, when it runs.
    pub(crate) fn ros2(&self) -> Option<&crate::http::ros2_stats::Ros2Stats> {
        self.options().ros2.as_deref()
    }

    /// Where recordings are written.
    pub(crate) fn recordings_dir(&self) -> std::path::PathBuf {
        self.options().recordings_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("jointd-recordings-{}", std::process::id()))
        })
    }

    pub fn limits(&self, bus: &str, id: u8) -> JointLimits {
        self.inner.limits.for_joint(bus, id)
    }

    /// Whether the daemon manages device `id` of `bus`: one of the bus's
    /// configured ids, or any device on a bus configured with none.
    pub(crate) fn managed(&self, bus: &str, id: u8) -> bool {
        self.options()
            .managed
            .get(bus)
            .filter(|ids| !ids.is_empty())
            .map_or(true, |ids| ids.contains(&id))
    }

    /// The calibration of joint `id` on `bus`: how its angles read at the API.
    pub(crate) fn calibration(&self, bus: &str, id: u8) -> crate::hands::Calibration {
        self.hands()
            .map_or(crate::hands::Calibration::IDENTITY, |store| {
                store.calibration(bus, id)
            })
    }

    /// The daemon's options beyond buses, limits and token (set once, at
    /// start; a second call is refused and gets its options back).
    pub fn set_options(&self, options: StateOptions) -> Result<(), Box<StateOptions>> {
        self.inner.options.set(options).map_err(Box::new)
    }

    fn options(&self) -> &StateOptions {
        static DEFAULTS: std::sync::OnceLock<StateOptions> = std::sync::OnceLock::new();
        self.inner
            .options
            .get()
            .unwrap_or_else(|| DEFAULTS.get_or_init(StateOptions::default))
    }

    /// Serve the dashboard from this folder instead of the embedded copy.
    pub fn web_dir(&self) -> Option<&std::path::PathBuf> {
        self.options().web_dir.as_ref()
    }

    /// The configured name of a joint (`[[joint]]` in the config file).
    pub fn joint_name(&self, bus: &str, id: u8) -> Option<&str> {
        let names = &self.options().joint_names;
        names
            .get(&(Some(bus.to_owned()), id))
            .or_else(|| names.get(&(None, id)))
            .map(String::as_str)
    }

    /// What applies to a WebSocket client that streams setpoints without
    /// declaring a watchdog of its own.
    pub fn watchdog_default(&self) -> WatchdogDefault {
        self.options().watchdog
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

    pub fn uptime_s(&self) -> f64 {
        self.inner.started.elapsed().as_secs_f64()
    }
}

/// A device id from a path or body: 1..=159, else 422 naming the range.
pub fn device_id(field: &str, id: i64) -> ApiResult<u8> {
    u8::try_from(id)
        .ok()
        .filter(|id| is_device_id(*id))
        .ok_or_else(|| {
            ApiError::out_of_range(
                field,
                id as f64,
                (f64::from(MIN_DEVICE_ID), f64::from(MAX_DEVICE_ID)),
                "",
            )
        })
}

/// The snapshot entry of a device, or 404; 503 when the bus is down (a bus
/// whose port is missing knows no device, and saying "unknown device" would
/// send the user scanning instead of plugging the adapter in).
pub fn known_device(snap: &BusSnapshot, id: u8) -> ApiResult<&DeviceState> {
    if let (None, LinkState::Down { reason, .. }) = (snap.devices.get(&id), &snap.link) {
        return Err(BusError::Down {
            bus: snap.name.clone(),
            reason: reason.clone(),
        }
        .into());
    }
    snap.devices.get(&id).ok_or_else(|| {
        ApiError::not_found(
            "unknown-device",
            format!(
                "device {id} is not known on bus {} (scan the bus to discover devices)",
                snap.name
            ),
        )
    })
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
        Some(f) => Err(ApiError::invalid(
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
        None => Err(ApiError::conflict(
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
