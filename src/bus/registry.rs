//! What the owner knows about each device: latest telemetry, online or not,
//! the target it was last sent, its mode, and the counts behind its rates.
//!
//! The registry turns replies and missed polls into state changes and
//! [`BusEvent`]s; it never touches the port.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::protocol::status::{active_fault, fault_name, fsm, fsm_name};
use crate::protocol::{CtrlMode, Info01, Reply, ReplyBody};

use super::coalesce::SlotInfo;
use super::events::BusEvent;
use super::firmware::DeviceFirmware;
use super::poll::PollState;
use super::setpoints::Setpoint;
use super::state::{DeviceState, DisabledReason, ResetRecord, ResetSignal};

/// States in which a joint module powers its motor (SPEC §5 fsm; rev
/// 2.0.8's `6 start` included).
pub(crate) fn drives_motor(state: u8) -> bool {
    const START: u8 = 6;
    matches!(state, fsm::ALIGN | START | fsm::RUN)
}

/// States a device is in after power-up (SPEC §5: ready; rev 2.0.8's
/// `1 init` and `2 precharge` on the way there).
fn power_up_state(state: u8) -> bool {
    const INIT: u8 = 1;
    const PRECHARGE: u8 = 2;
    matches!(state, fsm::READY | INIT | PRECHARGE)
}

/// One device as the owner tracks it.
#[derive(Debug, Clone)]
pub(crate) struct Entry {
    /// What snapshots publish.
    pub state: DeviceState,
    pub poll: PollState,
    /// Latest angle from INFO_01/INFO_02; cleared when the zero moves.
    pub measured: Option<(i16, Instant)>,
    /// When a frame last carried a new target to it.
    last_sent: Option<Instant>,
    /// The daemon believes the device drives its motor: an INFO_01 said so
    /// and nothing of the daemon's disabled it since. A power-up state
    /// seen meanwhile is a reset.
    believed_enabled: bool,
    /// The daemon disabled it and no INFO_01 has shown it stopped yet: a
    /// reply showing it driving may have left the device before the
    /// disable reached it, and is no reason to believe it enabled.
    disable_unconfirmed: bool,
    /// When the daemon last disabled it (just before the frames went): a
    /// reply to a request written before then tells the state the device
    /// was in before the disable, neither that it stopped nor that it runs
    /// (behind a USB adapter such replies come after the disable).
    disabled_at: Option<Instant>,
    /// The daemon has sent it an enable: a first INFO_01 showing it driving
    /// is that enable's doing, not a joint found enabled at start.
    enabled_by_daemon: bool,
    control_updates: u32,
    telemetry_samples: u32,
    /// Firmware probes (INFO_07 reads) in a row it left unanswered while
    /// answering its polls: enough of them make it V2.0.1.
    pub probe_silences: u32,
}

impl Entry {
    fn new(dev_id: u8) -> Self {
        Self {
            state: DeviceState {
                dev_id,
                ..DeviceState::default()
            },
            poll: PollState::default(),
            measured: None,
            last_sent: None,
            believed_enabled: false,
            disable_unconfirmed: false,
            disabled_at: None,
            enabled_by_daemon: false,
            control_updates: 0,
            telemetry_samples: 0,
            probe_silences: 0,
        }
    }
}

/// What a reply changed that the owner must act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct ReplyEffect {
    /// The device reset (power cut, reboot): it lost its target and its
    /// enable; whatever waited to go to it is stale.
    pub reset: bool,
    /// ... and it announced its power-up, so it runs the power-up mode
    /// (position). A reset only inferred from a dropped state may be a
    /// disable the daemon did not see: the mode the daemon set stands.
    pub powered_up: bool,
    /// The device just entered its fault state: its target is void.
    pub faulted: bool,
    /// The first INFO_01 heard from it shows it driving its motor: enabled
    /// before the daemon started, holding a target the daemon does not know.
    pub found_enabled: bool,
    /// The device just finished aligning (fsm align → run). A reference sent
    /// while it aligned may not have taken (SPEC leaves it open; the
    /// simulator holds its angle at the end of align), so its target must go
    /// out again.
    pub now_running: bool,
}

/// Every device of one bus, by id.
#[derive(Debug)]
pub(crate) struct Registry {
    bus: String,
    offline_after: u32,
    entries: BTreeMap<u8, Entry>,
}

impl Registry {
    pub(crate) fn new(bus: &str, offline_after: u32) -> Self {
        Self {
            bus: bus.to_string(),
            offline_after: offline_after.max(1),
            entries: BTreeMap::new(),
        }
    }

    /// The bus's name, for events.
    pub(crate) fn bus(&self) -> &str {
        &self.bus
    }

    /// Adds a device expected on the bus (offline until it answers).
    pub(crate) fn expect(&mut self, id: u8) {
        self.entries.entry(id).or_insert_with(|| Entry::new(id));
    }

    pub(crate) fn ids(&self) -> Vec<u8> {
        self.entries.keys().copied().collect()
    }

    pub(crate) fn get(&self, id: u8) -> Option<&Entry> {
        self.entries.get(&id)
    }

    pub(crate) fn is_online(&self, id: u8) -> bool {
        self.entries.get(&id).is_some_and(|e| e.state.online)
    }

    pub(crate) fn online_ids(&self) -> Vec<u8> {
        self.entries
            .values()
            .filter(|e| e.state.online)
            .map(|e| e.state.dev_id)
            .collect()
    }

    /// `(id, online, poll state)` of every device, for the poll planner.
    pub(crate) fn poll_states(&mut self) -> impl Iterator<Item = (u8, bool, &mut PollState)> {
        self.entries
            .iter_mut()
            .map(|(id, e)| (*id, e.state.online, &mut e.poll))
    }

    /// What the coalescer needs to fill a broadcast slot.
    pub(crate) fn slot_info(&self, id: u8) -> Option<SlotInfo> {
        self.entries.get(&id).map(|e| SlotInfo {
            speed_mode: e.state.mode == Some(CtrlMode::Speed),
            target: e.state.target_sent,
            target_known: e.state.target_known,
            measured: e.measured.map(|(angle, _)| angle),
            last_sent: e.last_sent,
        })
    }

    /// Takes in a reply. `solicited` is false for a frame nobody asked for:
    /// a power-up INFO_01.
    #[cfg(test)]
    pub(crate) fn on_reply(
        &mut self,
        reply: &Reply,
        now: Instant,
        solicited: bool,
        events: &mut Vec<BusEvent>,
    ) -> ReplyEffect {
        self.on_reply_asked(reply, now, solicited, None, events)
    }

    /// [`Self::on_reply`] of the reply to a request written before `asked`
    /// (`None`: written after anything the daemon did to the device).
    pub(crate) fn on_reply_asked(
        &mut self,
        reply: &Reply,
        now: Instant,
        solicited: bool,
        asked: Option<Instant>,
        events: &mut Vec<BusEvent>,
    ) -> ReplyEffect {
        let Registry { bus, entries, .. } = self;
        let entry = entries
            .entry(reply.dev_id)
            .or_insert_with(|| Entry::new(reply.dev_id));
        mark_online(bus, entry, events);
        match reply.body() {
            ReplyBody::Info01(info) => {
                let before_disable = asked
                    .zip(entry.disabled_at)
                    .is_some_and(|(asked, disabled)| asked <= disabled);
                let effect = if before_disable {
                    on_stale_info01(entry, &info, now)
                } else {
                    on_info01(bus, entry, &info, now, solicited, events)
                };
                entry.telemetry_samples += u32::from(solicited);
                effect
            }
            ReplyBody::Info02(info) => {
                entry.state.info02 = Some((info, now));
                entry.measured = Some((info.angle, now));
                entry.telemetry_samples += 1;
                ReplyEffect::default()
            }
            _ => ReplyEffect::default(),
        }
    }

    /// The daemon disabled the device (a request, an e-stop, its own stop):
    /// it holds no target of ours, and ready from now on is no reset.
    pub(crate) fn note_disabled(&mut self, id: u8, reason: DisabledReason) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.target_sent = None;
            e.state.target_known = true;
            e.state.disabled_reason = Some(reason);
            e.believed_enabled = false;
            e.disable_unconfirmed = true;
            e.disabled_at = Some(Instant::now());
        }
    }

    /// The daemon enabled the device: no reason to call it disabled.
    pub(crate) fn note_enabled(&mut self, id: u8) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.enabled_by_daemon = true;
            e.disable_unconfirmed = false;
            e.state.target_sent = None;
            e.state.target_known = true;
            e.state.disabled_reason = None;
        }
    }

    /// A poll or read of `id` went unanswered.
    pub(crate) fn on_missed(&mut self, id: u8, events: &mut Vec<BusEvent>) {
        let Some(entry) = self.entries.get_mut(&id) else {
            return;
        };
        entry.state.missed_polls = entry.state.missed_polls.saturating_add(1);
        // A device that misses polls too says nothing by missing a probe.
        entry.probe_silences = 0;
        if entry.state.online && entry.state.missed_polls >= self.offline_after {
            entry.state.online = false;
            entry.poll.retry_at = None;
            events.push(BusEvent::DeviceOffline {
                bus: self.bus.clone(),
                dev_id: id,
            });
        }
    }

    /// The port is gone: nobody can be heard.
    pub(crate) fn all_offline(&mut self, events: &mut Vec<BusEvent>) {
        for (id, entry) in &mut self.entries {
            if entry.state.online {
                entry.state.online = false;
                entry.poll.retry_at = None;
                events.push(BusEvent::DeviceOffline {
                    bus: self.bus.clone(),
                    dev_id: *id,
                });
            }
        }
    }

    /// A frame carrying `setpoint` to `id` was written at `at`.
    pub(crate) fn record_sent(&mut self, id: u8, setpoint: Setpoint, at: Instant) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.target_sent = Some(setpoint);
            e.state.target_known = true;
            e.last_sent = Some(at);
            e.control_updates += 1;
        }
    }

    /// The device holds no target of ours any more (disabled, mode change).
    pub(crate) fn forget_target(&mut self, id: u8) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.target_sent = None;
        }
    }

    /// The device's zero moved (jog, re-zero): old angles and targets mean
    /// something else now.
    pub(crate) fn zero_moved(&mut self, id: u8) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.target_sent = None;
            e.measured = None;
        }
    }

    pub(crate) fn set_mode(&mut self, id: u8, mode: CtrlMode) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.mode = Some(mode);
            e.state.target_sent = None;
        }
    }

    /// After an id change the entry moves with the device.
    pub(crate) fn rename(&mut self, old: u8, new: u8) {
        if let Some(mut e) = self.entries.remove(&old) {
            e.state.dev_id = new;
            self.entries.insert(new, e);
        }
    }

    /// Turns the counts of the window just ended into rates.
    pub(crate) fn roll_rates(&mut self, window: Duration) {
        let secs = window.as_secs_f64().max(f64::EPSILON);
        for e in self.entries.values_mut() {
            e.state.control_hz = f64::from(e.control_updates) / secs;
            e.state.telemetry_hz = f64::from(e.telemetry_samples) / secs;
            e.control_updates = 0;
            e.telemetry_samples = 0;
        }
    }

    /// Online devices whose firmware revision nobody has told yet.
    pub(crate) fn firmware_unknown(&self) -> Vec<u8> {
        self.entries
            .values()
            .filter(|e| e.state.online && e.state.firmware.is_none())
            .map(|e| e.state.dev_id)
            .collect()
    }

    /// A firmware probe of `id` went unanswered; returns how many in a row.
    pub(crate) fn probe_silence(&mut self, id: u8) -> u32 {
        self.entries.get_mut(&id).map_or(0, |e| {
            e.probe_silences += 1;
            e.probe_silences
        })
    }

    pub(crate) fn set_firmware(&mut self, id: u8, firmware: DeviceFirmware) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.state.firmware = Some(firmware);
        }
    }

    pub(crate) fn device_states(&self) -> BTreeMap<u8, DeviceState> {
        self.entries
            .iter()
            .map(|(id, e)| (*id, e.state.clone()))
            .collect()
    }
}

fn mark_online(bus: &str, entry: &mut Entry, events: &mut Vec<BusEvent>) {
    entry.state.missed_polls = 0;
    entry.poll.retry_at = None;
    if !entry.state.online {
        entry.state.online = true;
        events.push(BusEvent::DeviceOnline {
            bus: bus.to_string(),
            dev_id: entry.state.dev_id,
        });
    }
}

/// An INFO_01: reset, fault and end of align detection, then the state.
fn on_info01(
    bus: &str,
    entry: &mut Entry,
    info: &Info01,
    now: Instant,
    solicited: bool,
    events: &mut Vec<BusEvent>,
) -> ReplyEffect {
    let before = entry.state.info01.map(|(i, _)| i.fsm);
    let mut effect = ReplyEffect::default();
    if let Some(seen) = reset_signal(entry, info, solicited) {
        note_reset(bus, entry, info, seen, now, events);
        effect.reset = true;
        effect.powered_up = seen == ResetSignal::Announcement;
    }
    effect.faulted = note_fault(bus, entry, info, events);
    effect.now_running = before == Some(fsm::ALIGN) && info.fsm == fsm::RUN;
    let driving = drives_motor(info.fsm);
    // The first INFO_01 decides whether the target is known; later, a
    // device not driving its motor holds no target at all.
    effect.found_enabled = before.is_none() && driving && !entry.enabled_by_daemon;
    if before.is_none() || !driving {
        entry.state.target_known = !driving;
    }
    if !driving {
        entry.disable_unconfirmed = false;
    } else if !entry.disable_unconfirmed {
        entry.believed_enabled = true;
        entry.state.disabled_reason = None;
    }
    entry.state.info01 = Some((*info, now));
    entry.measured = Some((info.angle, now));
    effect
}

/// An INFO_01 asked for before the daemon's last disable of the device:
/// what it shows is kept (the latest heard), but it says nothing of the
/// device since the disable (no reset, no confirmed stop, not enabled).
fn on_stale_info01(entry: &mut Entry, info: &Info01, now: Instant) -> ReplyEffect {
    entry.state.info01 = Some((*info, now));
    entry.measured = Some((info.angle, now));
    ReplyEffect::default()
}

/// A device in a power-up state that announced itself again (it was heard
/// before: not its first announcement), or that the daemon believed
/// enabled. An announcement showing the motor driven is no power-up: a
/// late reply nobody waited for.
fn reset_signal(entry: &Entry, info: &Info01, solicited: bool) -> Option<ResetSignal> {
    if !power_up_state(info.fsm) {
        return None;
    }
    let heard_before = entry.state.info01.is_some() || entry.state.info02.is_some();
    if !solicited && heard_before {
        Some(ResetSignal::Announcement)
    } else if entry.believed_enabled {
        Some(ResetSignal::StateDropped)
    } else {
        None
    }
}

/// The device reset: disabled, no target (position mode when it announced
/// its power-up); reported.
fn note_reset(
    bus: &str,
    entry: &mut Entry,
    info: &Info01,
    seen: ResetSignal,
    now: Instant,
    events: &mut Vec<BusEvent>,
) {
    let fsm_before = entry.state.info01.map(|(i, _)| i.fsm);
    let s = &mut entry.state;
    if seen == ResetSignal::Announcement {
        s.mode = None;
    }
    s.target_sent = None;
    s.target_known = true;
    s.disabled_reason = Some(DisabledReason::Reset);
    s.resets += 1;
    s.last_reset = Some(ResetRecord {
        seen,
        fsm_before,
        fsm: info.fsm,
        at: now,
    });
    entry.believed_enabled = false;
    events.push(BusEvent::DeviceReset {
        bus: bus.to_string(),
        dev_id: s.dev_id,
        seen,
        state_before: fsm_before.map_or("unknown", fsm_name),
        state: fsm_name(info.fsm),
    });
}

/// Reports a fault when the device enters one (not on every poll while in
/// it). True when it just entered its fault state: its target is void.
fn note_fault(bus: &str, entry: &mut Entry, info: &Info01, events: &mut Vec<BusEvent>) -> bool {
    let active = |i: &Info01| (i.fsm == fsm::FAULT, active_fault(i.err_code));
    let was = entry.state.info01.as_ref().map(|(i, _)| active(i));
    let now = active(info);
    let faulty = now.0 || now.1 != 0;
    if faulty && was != Some(now) {
        events.push(BusEvent::Fault {
            bus: bus.to_string(),
            dev_id: entry.state.dev_id,
            err_code: info.err_code,
            name: fault_name(now.1),
        });
    }
    let entered = now.0 && was.map(|w| w.0) != Some(true);
    if entered {
        entry.state.target_sent = None;
        entry.state.disabled_reason = Some(DisabledReason::Fault);
    }
    entered
}

#[cfg(test)]
#[path = "registry_tests.rs"]
mod tests;
