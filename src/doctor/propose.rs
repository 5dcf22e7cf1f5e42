//! What jointd would run this bus with, and the rates to expect on it.
//!
//! The config: the stable path, the baud the devices answer at, the ids
//! found, the adapter named as found, the devices' protocol revision, the
//! turnaround measured on a native line, and confirmed writes off when the
//! adapter's count cannot be believed; every other key the daemon's
//! default. The rates are the daemon's own bounds:
//! - behind a USB adapter, the pipeline's cycle of the broadcasts and one
//!   poll in whole USB frames ([`AdapterModel::cycle_bound`], what
//!   `jointd bench` judges its runs against): control `1/T` per joint,
//!   telemetry `1/(T·joints)`;
//! - on a native line, the control share of the wire
//!   (`poll.control_share`) for the broadcasts and the rest for polls, each
//!   costing two frames, the turnaround and the host's reaction
//!   (docs/performance.md, "The frontier between control and telemetry").

use std::path::Path;
use std::time::Duration;

use serde::Serialize;

use crate::bus::config::{frame_time, AdapterSetting, BusConfig, PollPlan, Timing};
use crate::bus::firmware::FirmwareSetting;
use crate::transport::adapter::AdapterModel;

use super::check::{Check, CheckId, Spread};
use super::line::id_list;

/// What a host on a native line loses per poll between a reply's last byte
/// and its next write (a UART's or a pty's receive path handing the reply
/// over, the owner waking): what takes the measured rates below the
/// wire's, 0.97–0.99 of it (docs/performance.md, the memory and pty runs).
const HOST_REACTION: Duration = Duration::from_micros(40);
/// A turnaround measured this far above the configured one is proposed
/// (less is the host's read lag, which a pty or a loaded UART adds to
/// every measure).
const TURNAROUND_SLACK: Duration = Duration::from_micros(150);
/// Ids one broadcast frame of a kind reaches (SPEC §3.2: 1–8, 9–16).
const GROUP: u8 = 8;
/// The highest id a broadcast reaches (SPEC §8).
const MAX_BROADCAST_ID: u8 = 16;
/// The name proposed for the bus.
const BUS_NAME: &str = "bus0";

/// The rates jointd should reach on this bus.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rates {
    pub adapter: String,
    pub baud: u32,
    pub joints: usize,
    /// `baud / 200`: frames the wire carries a second.
    pub wire_frames_per_s: f64,
    /// Frames one update of every joint's target takes (broadcasts, and
    /// a control frame for each id above 16).
    pub frames_per_update: u32,
    /// With a client streaming every joint's target: updates/s per joint.
    pub control_hz: f64,
    /// Telemetry samples/s per joint meanwhile.
    pub telemetry_hz: f64,
    /// Telemetry samples/s per joint with no target streaming.
    pub telemetry_idle_hz: f64,
    /// What bounds them, in words.
    pub bound: String,
}

/// The config and what to expect of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Proposal {
    pub config: BusConfig,
    /// `[[bus]]` for the config file.
    pub toml: String,
    pub rates: Rates,
    /// Why a key differs from its default.
    pub notes: Vec<String>,
}

/// What the proposal is made from.
#[derive(Debug, Clone)]
pub(crate) struct Inputs<'a> {
    pub path: &'a Path,
    pub baud: u32,
    pub ids: Vec<u8>,
    pub adapter: AdapterModel,
    /// The adapter's count can be believed (or there is none).
    pub usb_confirm: bool,
    /// The devices' turnaround as measured on a native line.
    pub turnaround: Option<Spread>,
    /// Each device's protocol revision (`2.0.1`, `2.0.8`).
    pub revisions: Vec<String>,
}

/// Broadcast frames a full update of `ids` takes, plus a control frame
/// for each id no broadcast reaches.
pub(crate) fn frames_per_update(ids: &[u8]) -> u32 {
    let group = |lo: u8| u32::from(ids.iter().any(|&id| (lo..lo + GROUP).contains(&id)));
    let beyond = ids.iter().filter(|&&id| id > MAX_BROADCAST_ID).count() as u32;
    group(1) + group(1 + GROUP) + beyond
}

/// The rates of `ids` at `baud` behind `adapter`, with `timing` and `plan`.
pub fn expected_rates(
    adapter: AdapterModel,
    baud: u32,
    ids: &[u8],
    timing: &Timing,
    plan: &PollPlan,
) -> Rates {
    let joints = ids.len().max(1) as f64;
    let tf = frame_time(baud);
    let ta = Duration::from_micros(timing.turnaround_us);
    let b = frames_per_update(ids).max(1);
    let wire = f64::from(baud) / 200.0;
    let per_s = |d: Duration| 1.0 / d.as_secs_f64().max(f64::EPSILON);
    let (control, telemetry, idle, bound) = if adapter.is_latent() {
        let cycle = adapter.cycle_bound(tf, ta, b);
        let poll_only = adapter.cycle_bound(tf, ta, 0);
        let bound = format!(
            "the adapter's cycle of {b} broadcasts and a poll in whole USB frames: {:.0} µs",
            cycle.as_secs_f64() * 1e6
        );
        (
            per_s(cycle),
            per_s(cycle) / joints,
            per_s(poll_only) / joints,
            bound,
        )
    } else {
        let poll = tf * 2 + ta + HOST_REACTION;
        let share = plan.control_share;
        let bound = format!(
            "control takes {share} of the wire ({b} frames an update), polls the rest at {:.0} µs each",
            poll.as_secs_f64() * 1e6
        );
        let control = share * wire / f64::from(b);
        (
            control,
            (1.0 - share) * per_s(poll) / joints,
            per_s(poll) / joints,
            bound,
        )
    };
    Rates {
        adapter: adapter.to_string(),
        baud,
        joints: ids.len(),
        wire_frames_per_s: wire,
        frames_per_update: b,
        control_hz: control,
        telemetry_hz: telemetry,
        telemetry_idle_hz: idle,
        bound,
    }
}

/// The config jointd would run with, its TOML and its rates.
pub(crate) fn propose(inp: &Inputs<'_>) -> Proposal {
    let mut notes = Vec::new();
    let mut cfg = BusConfig::new(BUS_NAME, inp.path, inp.baud);
    cfg.ids = inp.ids.clone();
    cfg.ids.sort_unstable();
    cfg.ids.dedup();
    cfg.adapter = AdapterSetting::Fixed(inp.adapter);
    cfg.firmware = firmware_of(&inp.revisions, &mut notes);
    if !inp.usb_confirm {
        cfg.timing.usb_confirm = false;
        notes.push("usb_confirm = false: the adapter's output count cannot be believed".into());
    }
    if let Some(turn) = proposed_turnaround(inp.turnaround.as_ref(), &cfg.timing) {
        notes.push(format!(
            "turnaround_us = {}: the devices took at least that long to answer (less the host's reaction)",
            turn.as_micros()
        ));
        cfg.timing.turnaround_us = turn.as_micros() as u64;
    }
    let rates = expected_rates(inp.adapter, inp.baud, &cfg.ids, &cfg.timing, &cfg.poll);
    Proposal {
        toml: to_toml(&cfg),
        config: cfg,
        rates,
        notes,
    }
}

/// One revision for the bus when every device shares it, else `auto`.
fn firmware_of(revisions: &[String], notes: &mut Vec<String>) -> FirmwareSetting {
    let first = revisions
        .first()
        .and_then(|r| FirmwareSetting::parse(r).ok());
    match first {
        Some(s)
            if revisions
                .iter()
                .all(|r| FirmwareSetting::parse(r).ok() == Some(s)) =>
        {
            s
        }
        Some(_) => {
            notes.push("firmware = \"auto\": the devices run different protocol revisions".into());
            FirmwareSetting::Auto
        }
        None => FirmwareSetting::Auto,
    }
}

/// A turnaround to propose: the least measured less the host's reaction,
/// in 10 µs, when it is well above the configured one. The least, not the
/// median: every sample is the device's turnaround plus the host's read
/// lag, which is never negative and on a loaded host (a pty most of all)
/// runs to milliseconds at the median while its least stays small.
fn proposed_turnaround(measured: Option<&Spread>, timing: &Timing) -> Option<Duration> {
    let least = Duration::from_secs_f64(measured?.min_us.max(0.0) / 1e6);
    let now = Duration::from_micros(timing.turnaround_us);
    let device = least.saturating_sub(HOST_REACTION);
    (device > now + TURNAROUND_SLACK).then(|| {
        let tens = device.as_micros().div_ceil(10) as u64;
        Duration::from_micros(tens * 10)
    })
}

/// `[[bus]]` with the keys the doctor decided; the rest is the default.
fn to_toml(cfg: &BusConfig) -> String {
    let quoted = |s: &str| serde_json::to_string(s).unwrap_or_else(|_| format!("\"{s}\""));
    let ids: Vec<String> = cfg.ids.iter().map(u8::to_string).collect();
    let adapter = match cfg.adapter {
        AdapterSetting::Fixed(m) => m.to_string(),
        AdapterSetting::Auto => "auto".into(),
    };
    let mut text = format!(
        "[[bus]]\nname = {}                    # name it after what it drives, e.g. \"right_hand\"\n\
         path = {}\nbaud = {}\nids = [{}]\nadapter = {}\nfirmware = {}\n",
        quoted(&cfg.name),
        quoted(&cfg.path.display().to_string()),
        cfg.baud,
        ids.join(", "),
        quoted(&adapter),
        quoted(cfg.firmware.name()),
    );
    let default = Timing::default();
    let mut timing = String::new();
    if cfg.timing.turnaround_us != default.turnaround_us {
        timing.push_str(&format!("turnaround_us = {}\n", cfg.timing.turnaround_us));
    }
    if cfg.timing.usb_confirm != default.usb_confirm {
        timing.push_str(&format!("usb_confirm = {}\n", cfg.timing.usb_confirm));
    }
    if !timing.is_empty() {
        text.push_str("\n[bus.timing]\n");
        text.push_str(&timing);
    }
    text
}

/// The proposal as a check: what jointd will run with, and at what rates.
pub(crate) fn proposal_check(p: &Proposal) -> Check {
    let r = &p.rates;
    Check::ok(
        CheckId::Proposal,
        format!(
            "ids {} at {} baud behind {}: with every target streaming, {:.0} control updates/s \
             and {:.1} telemetry samples/s per joint; polling alone, {:.1}/s per joint",
            id_list(&p.config.ids),
            r.baud,
            r.adapter,
            r.control_hz,
            r.telemetry_hz,
            r.telemetry_idle_hz,
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rates(adapter: AdapterModel, baud: u32, joints: u8) -> Rates {
        let ids: Vec<u8> = (1..=joints).collect();
        expected_rates(
            adapter,
            baud,
            &ids,
            &Timing::default(),
            &PollPlan::default(),
        )
    }

    #[test]
    fn native_rates_match_the_measured_frontier() {
        // docs/performance.md: 425 / 43–45 at 500000, 195.8 / 21.6–22.2 at 230400.
        let r = rates(AdapterModel::Native, 500_000, 16);
        assert!((r.control_hz - 425.0).abs() < 0.5, "{r:?}");
        assert!((42.0..46.0).contains(&r.telemetry_hz), "{r:?}");
        let r = rates(AdapterModel::Native, 230_400, 16);
        assert!((r.control_hz - 195.8).abs() < 0.5, "{r:?}");
        assert!((21.0..23.0).contains(&r.telemetry_hz), "{r:?}");
    }

    #[test]
    fn usb_rates_are_the_benchs_bound() {
        // 500 / 31.2 on 1 ms frames, 571 / 35.7 on FT232H (docs/performance.md).
        let r = rates(AdapterModel::Ch340, 500_000, 16);
        assert!((r.control_hz - 500.0).abs() < 1e-6 && (r.telemetry_hz - 31.25).abs() < 1e-6);
        let r = rates(AdapterModel::Ft232h { latency_ms: 1 }, 500_000, 16);
        assert!((r.control_hz - 571.43).abs() < 0.01, "{r:?}");
    }

    #[test]
    fn an_update_takes_a_broadcast_per_group_and_a_frame_per_id_above_16() {
        assert_eq!(frames_per_update(&[1, 2, 3]), 1);
        assert_eq!(frames_per_update(&[1, 9]), 2);
        assert_eq!(frames_per_update(&[9, 20, 21]), 3);
    }

    #[test]
    fn the_toml_names_what_was_found_and_parses_back() {
        let p = propose(&Inputs {
            path: Path::new("/dev/serial/by-id/usb-FTDI_X-if00-port0"),
            baud: 500_000,
            ids: vec![2, 1],
            adapter: AdapterModel::Cp2102,
            usb_confirm: false,
            turnaround: None,
            revisions: vec!["2.0.1".into(), "2.0.1".into()],
        });
        assert!(
            p.toml.contains("ids = [1, 2]") && p.toml.contains("usb_confirm = false"),
            "{}",
            p.toml
        );
        // The daemon's `[[bus]]` table, read as it reads it.
        #[derive(serde::Deserialize)]
        struct File {
            bus: Vec<BusConfig>,
        }
        let file: File = toml::from_str(&p.toml).expect("the daemon reads it");
        assert_eq!(file.bus, vec![p.config.clone()]);
    }

    #[test]
    fn a_slow_turnaround_is_proposed_and_a_fast_one_left() {
        let spread = |us: u64| Spread::of(&[Duration::from_micros(us)]);
        let t = Timing::default();
        assert_eq!(
            proposed_turnaround(spread(500).as_ref(), &t),
            Some(Duration::from_micros(460))
        );
        assert_eq!(proposed_turnaround(spread(260).as_ref(), &t), None);
        // A loaded host's read lag: most samples late, the least not.
        let lagged: Vec<Duration> = [150, 1300, 1400, 1350, 1500]
            .map(Duration::from_micros)
            .to_vec();
        assert_eq!(proposed_turnaround(Spread::of(&lagged).as_ref(), &t), None);
    }
}
