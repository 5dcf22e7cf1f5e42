//! Configuration of one bus: where the port is, how fast it talks, which
//! devices to expect, how to share the wire between control and telemetry,
//! and how long to wait for a reply.
//!
//! Every field but `name`, `path` and `baud` has a default, so a config file
//! may name only what it changes; on the command line a bus is `PATH@BAUD`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::protocol::{is_device_id, BaudLevel, MAX_DEVICE_ID, MIN_DEVICE_ID};
use crate::transport::adapter::AdapterModel;

use super::error::BusError;
use super::firmware::{FirmwarePolicy, FirmwareSetting};

/// Low among real-time priorities: above every normal thread, below the
/// kernel's own real-time work.
pub(crate) const DEFAULT_RT_PRIORITY: u8 = 10;

/// The factory baud of the modules (SPEC §1, level 1).
pub(crate) const FACTORY_BAUD: u32 = 230_400;

/// One serial bus and how the owner drives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusConfig {
    /// Name in the API and in logs (`/api/v1/buses/{name}`).
    pub name: String,
    /// Any tty: `/dev/ttyUSB0`, a `/dev/serial/by-id/…` link, a pty made by another program.
    pub path: PathBuf,
    /// One of SPEC §1's rates.
    pub baud: u32,
    /// Devices expected on this bus; empty = scan `scan_first..=scan_last` at start.
    #[serde(default)]
    pub ids: Vec<u8>,
    #[serde(default = "default_scan_first")]
    pub scan_first: u8,
    #[serde(default = "default_scan_last")]
    pub scan_last: u8,
    #[serde(default)]
    pub poll: PollPlan,
    #[serde(default)]
    pub timing: Timing,
    /// What the joints are left in when the daemon stops.
    #[serde(default)]
    pub on_shutdown: ShutdownState,
    /// What the daemon does with a joint it finds enabled at start (the
    /// first INFO_01 it hears from it shows align or run).
    #[serde(default)]
    pub on_start: StartPolicy,
    /// Ask the kernel for RS-485 direction control (driver enable on RTS
    /// while sending) where the serial driver offers it. A port already set
    /// up for RS-485 (device tree, `setserial`) keeps its settings; `false`
    /// leaves the port's RS-485 settings alone.
    #[serde(default = "default_rs485")]
    pub rs485: bool,
    /// The devices' protocol revision: `auto` (ask each device once, the
    /// default), `2.0.1` or `2.0.8` (see [`super::firmware`]).
    #[serde(default)]
    pub firmware: FirmwareSetting,
    /// Per device where a bus mixes revisions, e.g. `{ "9-16" = "2.0.1" }`.
    #[serde(default)]
    pub firmware_by_id: BTreeMap<String, FirmwareSetting>,
    /// The USB adapter in front of the bus: `auto` (found from sysfs when the
    /// port opens, the default) or `native`, `ftdi[:MS]`, `ch340`, `cp2102`,
    /// `ft232h[:MS]` (see [`crate::transport::adapter`]).
    #[serde(default)]
    pub adapter: AdapterSetting,
}

/// Which adapter timing the bus plans for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AdapterSetting {
    /// What sysfs says when the port opens (native for a pty or a UART).
    #[default]
    Auto,
    /// This model, whatever sysfs says.
    Fixed(AdapterModel),
}

impl AdapterSetting {
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.trim() {
            "auto" => Ok(Self::Auto),
            t => AdapterModel::parse(t).map(Self::Fixed),
        }
    }
}

impl Serialize for AdapterSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Auto => s.serialize_str("auto"),
            Self::Fixed(m) => s.serialize_str(&m.to_string()),
        }
    }
}

impl<'de> Deserialize<'de> for AdapterSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Self::parse(&text).map_err(serde::de::Error::custom)
    }
}

fn default_rs485() -> bool {
    true
}

/// The safe state a bus leaves its joints in when the daemon stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShutdownState {
    /// Disable every joint (release the motors).
    #[default]
    Disable,
    /// Leave enabled joints holding their last target (a grasp survives a
    /// daemon restart). Modules that watch for a silent host may report
    /// err 10, communication lost, once polling stops.
    Hold,
}

/// What the daemon does with a joint found enabled at start: one left
/// enabled by a daemon stopped with `on_shutdown = "hold"`, killed, or by
/// another tool. It holds a target nobody in this daemon set, and may still
/// be moving towards it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StartPolicy {
    /// Disable it (release the motor) before anything else on the bus: the
    /// daemon cannot know what it is doing, and no client supervises it
    /// yet. The state a stop with the default `on_shutdown` leaves too.
    #[default]
    Disable,
    /// Leave it enabled, its target shown as unknown until a client sends
    /// one (the partner of `on_shutdown = "hold"`: a grasp survives a
    /// restart). Its broadcast group moves only with per-joint frames
    /// meanwhile, so nothing overwrites its target.
    Keep,
}

fn default_scan_first() -> u8 {
    MIN_DEVICE_ID
}

fn default_scan_last() -> u8 {
    MAX_DEVICE_ID
}

/// How the wire left over by control is spent on telemetry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PollPlan {
    /// Largest share of wire time control frames may take while telemetry
    /// wants the wire (0..=1). Control takes everything when there is nothing
    /// to poll; polls take everything control leaves.
    ///
    /// 0.34 gives 16 joints at 500000 baud ~425 control updates/s each (two
    /// broadcasts per update) and, with ~5 % of the time lost to the host's
    /// reaction after replies, ~42 telemetry samples/s each.
    pub control_share: f64,
    /// Every Nth poll of a device reads INFO_01 (state, faults) instead of INFO_02.
    pub info01_every: u32,
    /// Consecutive missed polls after which a device is offline.
    pub offline_after: u32,
    /// How often an offline device is asked whether it is back, milliseconds.
    pub offline_poll_ms: u64,
    /// How often the snapshot watch is refreshed, milliseconds.
    pub snapshot_ms: u64,
}

impl Default for PollPlan {
    fn default() -> Self {
        Self {
            control_share: 0.34,
            info01_every: 8,
            offline_after: 3,
            offline_poll_ms: 200,
            snapshot_ms: 10,
        }
    }
}

/// Reply timing. The timeout of a transaction is
/// `last byte of the request + turnaround + reply frame + reply_margin`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Timing {
    /// The devices' turnaround (request's last byte to reply's first), µs.
    /// Counted as busy wire time; undocumented by the vendor (SPEC §1).
    pub turnaround_us: u64,
    /// Slack on top of the modelled reply time before a reply counts as
    /// missing: OS and adapter latency (an FTDI latency timer is added to
    /// it). Generous on purpose: writing while a late reply is still on its
    /// way is a collision, and only a missing device pays for the wait.
    pub reply_margin_us: u64,
    /// Extra attempts of a one-shot transaction after a timeout (polls are not retried).
    pub retries: u32,
    /// How long before the line frees the next host frame is handed to the
    /// port, µs (at most ¾ of a frame time): enough to cover the OS's write
    /// latency so the line never idles between host frames, short enough
    /// to sample setpoints late.
    pub write_lead_us: u64,
    /// After a reply is due, how long the owner looks at the port without
    /// sleeping, µs (0: always sleep). Saves the wake-up after each reply
    /// for a few % of a core.
    pub reply_spin_us: u64,
    /// Real-time (SCHED_FIFO) priority of the owner thread, 0 = normal
    /// scheduling. It blocks on the port almost all the time, but when a
    /// reply comes it must run within tens of µs, even on a busy machine.
    /// Refused without CAP_SYS_NICE/RLIMIT_RTPRIO: logged, not fatal.
    pub rt_priority: u8,
    /// Behind a USB adapter: how long a backed-off pipeline must see no
    /// collision's aftermath before it steps back towards the adapter's
    /// bound, ms (doubled after a relapse, up to 16 times).
    pub usb_recover_ms: u64,
    /// Behind a USB adapter whose driver counts the bytes the adapter has
    /// not taken yet (`TIOCOUTQ` on a USB-serial tty): wait to see each
    /// blind write taken before the next, so a write that reaches the
    /// adapter late costs the frames it was late and never collides.
    /// Off: writes are trusted to arrive within the pipeline's guard, and
    /// late ones are learnt from what they leave behind.
    pub usb_confirm: bool,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            turnaround_us: 100,
            reply_margin_us: 5000,
            retries: 2,
            write_lead_us: 300,
            reply_spin_us: 150,
            rt_priority: DEFAULT_RT_PRIORITY,
            usb_recover_ms: 10_000,
            usb_confirm: true,
        }
    }
}

impl BusConfig {
    /// A bus with every default: scans the whole id range at start.
    pub fn new(name: impl Into<String>, path: impl Into<PathBuf>, baud: u32) -> Self {
        Self {
            name: name.into(),
            path: path.into(),
            baud,
            ids: Vec::new(),
            scan_first: default_scan_first(),
            scan_last: default_scan_last(),
            poll: PollPlan::default(),
            timing: Timing::default(),
            rs485: default_rs485(),
            on_shutdown: ShutdownState::default(),
            on_start: StartPolicy::default(),
            firmware: FirmwareSetting::default(),
            firmware_by_id: BTreeMap::new(),
            adapter: AdapterSetting::default(),
        }
    }

    /// The firmware setting of every device (checked by [`Self::validate`]).
    pub fn firmware_policy(&self) -> Result<FirmwarePolicy, String> {
        let pairs = self
            .firmware_by_id
            .iter()
            .map(|(ids, s)| (ids.as_str(), *s));
        FirmwarePolicy::with_ids(self.firmware, pairs)
    }

    /// Parses the command line form `[NAME=]PATH@BAUD` (`@BAUD` may be left
    /// out for the factory 230400). The name defaults to the path's file name.
    pub fn parse_cli(spec: &str) -> Result<Self, BusError> {
        let (name, rest) = match spec.split_once('=') {
            Some((name, rest)) if !name.is_empty() && !name.contains('/') => {
                (Some(name.to_string()), rest)
            }
            _ => (None, spec),
        };
        let (path, baud) = match rest.rsplit_once('@') {
            Some((path, baud)) => (path, parse_baud(baud)?),
            None => {
                // Said aloud: a bus that stays silent at the wrong baud
                // looks exactly like a bus with no devices.
                tracing::info!(
                    "bus `{spec}` has no @BAUD: assuming the factory {FACTORY_BAUD} baud; \
                     write `{rest}@500000` (or another baud) if the devices run at another"
                );
                (rest, FACTORY_BAUD)
            }
        };
        if path.is_empty() {
            return Err(BusError::Invalid(format!(
                "bus `{spec}`: expected [NAME=]PATH@BAUD, e.g. /dev/ttyUSB0@500000"
            )));
        }
        let path = PathBuf::from(path);
        let name = name.unwrap_or_else(|| {
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| path.display().to_string())
        });
        let cfg = Self::new(name, path, baud);
        cfg.validate()?;
        Ok(cfg)
    }

    /// Refuses what the owner cannot run with, saying which field and why.
    pub fn validate(&self) -> Result<(), BusError> {
        match self.invalid_field() {
            Some((_, why)) => Err(BusError::Invalid(format!("bus `{}`: {why}", self.name))),
            None => Ok(()),
        }
    }

    /// The first field the owner cannot run with: its key as the config
    /// file spells it (so the file's line can be found) and why.
    pub fn invalid_field(&self) -> Option<(&'static str, String)> {
        if BaudLevel::from_baud(self.baud).is_none() {
            return Some((
                "baud",
                format!("baud {} is not one of {}", self.baud, BAUD_LIST),
            ));
        }
        if let Some(id) = self.ids.iter().find(|id| !is_device_id(**id)) {
            return Some(("ids", format!("device id {id} is outside 1..=159")));
        }
        if !is_device_id(self.scan_first)
            || !is_device_id(self.scan_last)
            || self.scan_first > self.scan_last
        {
            let why = format!(
                "scan range {}..={} must lie within 1..=159",
                self.scan_first, self.scan_last
            );
            let key = if is_device_id(self.scan_first) {
                "scan_last"
            } else {
                "scan_first"
            };
            return Some((key, why));
        }
        let share = self.poll.control_share;
        if !(share > 0.0 && share <= 1.0) {
            return Some((
                "control_share",
                format!("control_share {share} must be in (0, 1]"),
            ));
        }
        if self.poll.info01_every == 0 {
            return Some(("info01_every", "info01_every must be at least 1".into()));
        }
        if self.poll.offline_after == 0 {
            return Some(("offline_after", "offline_after must be at least 1".into()));
        }
        if let Err(why) = self.firmware_policy() {
            return Some(("firmware_by_id", why));
        }
        None
    }

    /// Time one frame occupies the wire at the configured baud.
    pub fn frame_time(&self) -> Duration {
        frame_time(self.baud)
    }
}

/// The rates SPEC §1 allows, for error messages.
const BAUD_LIST: &str = "500000, 230400, 115200, 38400, 19200";

fn parse_baud(text: &str) -> Result<u32, BusError> {
    let baud: u32 = text
        .trim()
        .parse()
        .map_err(|_| BusError::Invalid(format!("baud `{text}` is not a number ({BAUD_LIST})")))?;
    match BaudLevel::from_baud(baud) {
        Some(_) => Ok(baud),
        None => Err(BusError::Invalid(format!(
            "baud {baud} is not one of {BAUD_LIST}"
        ))),
    }
}

/// Time one 20-byte frame occupies the wire (SPEC §1: 200 bit times),
/// to the nearest nanosecond.
pub(crate) fn frame_time(baud: u32) -> Duration {
    const BIT_NS_PER_FRAME: u64 = 200 * 1_000_000_000;
    let baud = u64::from(baud.max(1));
    Duration::from_nanos((BIT_NS_PER_FRAME + baud / 2) / baud)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cli_form_parses_path_baud_and_optional_name() {
        let c = BusConfig::parse_cli("/dev/ttyUSB0@500000").unwrap();
        assert_eq!(
            (c.name.as_str(), c.path.to_str(), c.baud),
            ("ttyUSB0", Some("/dev/ttyUSB0"), 500_000)
        );
        let c = BusConfig::parse_cli("left=/dev/pts/7@230400").unwrap();
        assert_eq!((c.name.as_str(), c.baud), ("left", 230_400));
        let c = BusConfig::parse_cli("/tmp/x/ttySIM0").unwrap();
        assert_eq!(c.baud, FACTORY_BAUD);
    }

    #[test]
    fn cli_form_refuses_bad_bauds_and_empty_paths() {
        assert!(BusConfig::parse_cli("/dev/ttyUSB0@9600").is_err());
        assert!(BusConfig::parse_cli("/dev/ttyUSB0@fast").is_err());
        assert!(BusConfig::parse_cli("@500000").is_err());
    }

    #[test]
    fn config_file_needs_only_name_path_baud() {
        let c: BusConfig = serde_json::from_str(
            r#"{"name":"b","path":"/dev/ttyUSB0","baud":500000,"poll":{"control_share":0.5}}"#,
        )
        .unwrap();
        assert_eq!(c.poll.control_share, 0.5);
        assert_eq!(c.poll.info01_every, PollPlan::default().info01_every);
        assert_eq!(c.timing, Timing::default());
        assert_eq!((c.scan_first, c.scan_last), (1, 159));
    }

    #[test]
    fn on_start_defaults_to_disable_and_reads_keep() {
        let c: BusConfig =
            serde_json::from_str(r#"{"name":"b","path":"/dev/ttyUSB0","baud":500000}"#).unwrap();
        assert_eq!(c.on_start, StartPolicy::Disable);
        let c: BusConfig = serde_json::from_str(
            r#"{"name":"b","path":"/dev/ttyUSB0","baud":500000,"on_start":"keep"}"#,
        )
        .unwrap();
        assert_eq!(c.on_start, StartPolicy::Keep);
    }

    #[test]
    fn validation_names_the_bad_field() {
        let mut c = BusConfig::new("b", "/dev/null", 500_000);
        c.ids = vec![1, 200];
        assert!(matches!(c.validate(), Err(BusError::Invalid(m)) if m.contains("200")));
        let mut c = BusConfig::new("b", "/dev/null", 500_000);
        c.poll.control_share = 0.0;
        assert!(c.validate().is_err());
    }

    #[test]
    fn frame_time_is_200_bit_times() {
        assert_eq!(frame_time(500_000), Duration::from_micros(400));
    }
}
