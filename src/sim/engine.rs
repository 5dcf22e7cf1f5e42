//! The simulated bus as a pure function of timestamps: host bytes go in with
//! their arrival instant, the line model places and referees them, devices
//! act on the frames that reach them intact, and reply bytes come out with
//! the instant they are due at the host. The runner thread supplies real
//! time and moves the bytes; tests can drive this directly with made-up
//! instants.

use std::time::{Duration, Instant};

use crate::protocol::{BaudLevel, Command, Frame, FrameBytes, StreamDecoder, ALL_DEVICES};

use super::config::{SimConfig, SimError};
use super::device::Device;
use super::faults::{collide, misframed, noise_frame, LineFaults};
use super::host_side::HostSide;
use super::log::{addressed_id, FrameLog, WireFrame};
use super::params::{FlashImage, FlashStore, Params};
use super::rng::Rng;
use super::stats::SimStats;
use super::view::DeviceView;
use super::wire::{frame_time, DeviceTx, HostTx, Wire, WireEvent};

mod inject;

/// Devices' physics is run at least this often, so no observer or frame
/// ever has to integrate a long idle stretch while holding the lock.
const TICK: Duration = Duration::from_millis(20);

/// Reply bytes due at the host at `due`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Delivery {
    pub due: Instant,
    pub bytes: FrameBytes,
}

#[derive(Debug)]
pub(crate) struct Engine {
    turnaround: Duration,
    default_baud: u32,
    devices: Vec<Device>,
    wire: Wire,
    decoder: StreamDecoder,
    faults: LineFaults,
    stats: SimStats,
    corrupted_host_frames: u64,
    log: FrameLog,
    flash: FlashStore,
    rng: Rng,
    unplugged: bool,
    /// The host's side of the line, as the runner saw it.
    pub(crate) host: HostSide,
    /// End of the last garbled transmission handed to the host: overlapping
    /// collided transmissions reach the host as one garbled frame.
    garbage_until: Option<Instant>,
    last_tick: Instant,
    /// The adapter echoes every host frame back to the host.
    echo: bool,
}

impl Engine {
    /// Powers the bus up at `now` (flash from the state file, if any).
    pub(crate) fn new(cfg: &SimConfig, now: Instant) -> Result<Self, SimError> {
        cfg.validate()?;
        let level = BaudLevel::from_baud(cfg.baud).ok_or(SimError::BadBaud(cfg.baud))?;
        let flash = FlashStore::new(cfg.state_file.clone());
        let saved = flash.load()?;
        let devices = Device::bus(cfg, &saved, Params::factory(level), now);
        Ok(Self {
            turnaround: cfg.turnaround,
            default_baud: cfg.baud,
            devices,
            wire: Wire::new(),
            decoder: StreamDecoder::new(),
            faults: LineFaults::default(),
            stats: SimStats::new(now),
            corrupted_host_frames: 0,
            log: FrameLog::new(cfg.log_capacity),
            flash,
            rng: Rng::new(cfg.seed),
            unplugged: false,
            host: HostSide::default(),
            garbage_until: None,
            last_tick: now,
            echo: cfg.echo,
        })
    }

    /// Bytes the host wrote, read at `at`, while its port was set to `host_baud`.
    pub(crate) fn on_host_bytes(&mut self, bytes: &[u8], at: Instant, host_baud: Option<u32>) {
        self.decoder.push(bytes);
        while let Some((_, fb)) = self.decoder.next_frame_with_bytes() {
            let dur = frame_time(host_baud.unwrap_or(self.default_baud));
            let p = self.wire.place_host(fb, at, host_baud, dur);
            self.stats.queued_ahead += u64::from(p.queued);
            self.stats.collisions += p.collisions;
        }
    }

    /// When something next happens on the line.
    pub(crate) fn next_event(&self) -> Option<Instant> {
        let announce = self.devices.iter().filter_map(Device::announce_at).min();
        let noise = self.faults.noise.map(|(_, next)| next);
        [self.wire.next_event(), announce, noise]
            .into_iter()
            .flatten()
            .min()
    }

    /// When bytes are next due at the host (the instant that needs precision).
    pub(crate) fn next_delivery(&self) -> Option<Instant> {
        self.wire.next_device_end()
    }

    /// Runs every device's physics up to `now` if it has not run for a while.
    pub(crate) fn tick(&mut self, now: Instant) {
        if now.saturating_duration_since(self.last_tick) >= TICK {
            self.devices.iter_mut().for_each(|d| d.advance_to(now));
            self.last_tick = now;
        }
    }

    /// Host frames waiting for or on the line.
    pub(crate) fn host_backlog(&self) -> usize {
        self.wire.host_backlog()
    }

    /// Runs everything due by `now`; returns the bytes due at the host, in order.
    /// `host_baud` is the host port's setting now (replies at another baud are garbage to it).
    pub(crate) fn advance(&mut self, now: Instant, host_baud: Option<u32>) -> Vec<Delivery> {
        let mut out = Vec::new();
        loop {
            let wire_t = self.wire.next_event().filter(|t| *t <= now);
            let announce = self.next_announcement(now);
            match (wire_t, announce) {
                (None, None) => break,
                (w, Some((t, slot))) if w.map_or(true, |w| t < w) => self.announce(slot, t),
                _ => match self.wire.pop_due(now) {
                    Some(WireEvent::Host(h)) => out.extend(self.on_host_frame(h)),
                    Some(WireEvent::Device(d)) => out.extend(self.deliver(d, host_baud)),
                    None => break,
                },
            }
        }
        self.wire.fold(now);
        if self.noise_due(now, &mut out) {
            out.sort_by_key(|d| d.due);
        }
        out
    }

    /// The noise bursts due by `now` ([`Fault::Noise`](super::faults::Fault::Noise)); true if any.
    fn noise_due(&mut self, now: Instant, out: &mut Vec<Delivery>) -> bool {
        let Some((every, mut next)) = self.faults.noise else {
            return false;
        };
        let mut any = false;
        while next <= now {
            out.push(Delivery {
                due: next,
                bytes: noise_frame(&mut self.rng),
            });
            self.stats.noise_bursts += 1;
            next += every;
            any = true;
        }
        self.faults.noise = Some((every, next));
        any
    }

    fn next_announcement(&self, now: Instant) -> Option<(Instant, usize)> {
        self.devices
            .iter()
            .filter_map(|d| d.announce_at().filter(|t| *t <= now).map(|t| (t, d.slot)))
            .min()
    }

    fn announce(&mut self, slot: usize, at: Instant) {
        let Some(dev) = self.devices.get_mut(slot) else {
            return;
        };
        let Some(reply) = dev.take_announcement(at) else {
            return;
        };
        let baud = dev.baud();
        let tx = DeviceTx {
            start: at,
            end: at + frame_time(baud),
            slot,
            dev_id: reply.dev_id,
            bytes: reply.encode(),
            baud,
            spontaneous: true,
            collided: false,
        };
        self.stats.collisions += self.wire.schedule_device(tx, Duration::ZERO);
    }

    /// A host frame has fully arrived: every device that heard it intact
    /// acts on it. Returns its echo, if the adapter echoes.
    fn on_host_frame(&mut self, h: HostTx) -> Option<Delivery> {
        self.stats.host_frames += 1;
        let echo = self.echo_of(&h);
        let cmd = Frame::decode(&h.bytes)
            .ok()
            .and_then(|f| Command::from_frame(&f).ok());
        self.log.push(WireFrame {
            start: h.start,
            end: h.end,
            from_host: true,
            dev_id: cmd.as_ref().and_then(addressed_id),
            bytes: h.bytes,
            collided: h.collided,
        });
        if h.collided {
            self.stats.collided_host_frames += 1;
            return echo;
        }
        let mut bytes = h.bytes;
        if self.faults.corrupt(&mut bytes, &mut self.rng) {
            self.corrupted_host_frames += 1;
            return echo;
        }
        let Some(cmd) = cmd else {
            self.stats.kinds.not_a_command += 1;
            return echo;
        };
        self.stats.kinds.count(&cmd);
        self.dispatch(&cmd, &h);
        echo
    }

    /// What an echoing adapter hands back of a host frame: the frame as it
    /// was on the wire (garbled if it collided), at the instant its last
    /// byte left. The adapter's own receiver listens at the host's baud.
    fn echo_of(&mut self, h: &HostTx) -> Option<Delivery> {
        if !self.echo || self.unplugged {
            return None;
        }
        self.stats.echoes += 1;
        let bytes = if h.collided {
            collide(&h.bytes, &noise_frame(&mut self.rng))
        } else {
            h.bytes
        };
        Some(Delivery { due: h.end, bytes })
    }

    fn dispatch(&mut self, cmd: &Command, h: &HostTx) {
        let mut mismatch = false;
        let mut persist = false;
        let lead = self.turnaround + self.faults.extra_turnaround;
        for slot in 0..self.devices.len() {
            let dev = &mut self.devices[slot];
            if h.baud != Some(dev.baud()) {
                mismatch = true;
                continue;
            }
            if let Command::Control(c) = cmd {
                let for_it = c.dev_id == dev.id || c.dev_id == ALL_DEVICES;
                if for_it && self.faults.misses_control(dev.id) {
                    self.stats.missed_control_frames += 1;
                    continue;
                }
            }
            let outcome = dev.handle(cmd, h.end);
            persist |= outcome.persist;
            let Some(reply) = outcome.reply else { continue };
            if self.faults.drops(reply.dev_id, &mut self.rng) {
                self.stats.dropped_replies += 1;
                continue;
            }
            let start = h.end + lead;
            let baud = h.baud.unwrap_or(self.default_baud);
            let tx = DeviceTx {
                start,
                end: start + frame_time(baud),
                slot,
                dev_id: reply.dev_id,
                bytes: reply.encode(),
                baud,
                spontaneous: false,
                collided: false,
            };
            self.stats.collisions += self.wire.schedule_device(tx, lead);
        }
        self.stats.baud_mismatches += u64::from(mismatch);
        if persist {
            self.save_flash();
        }
    }

    fn save_flash(&self) {
        let images: Vec<FlashImage> = self.devices.iter().map(Device::flash_image).collect();
        if let Err(e) = self.flash.save(&images) {
            tracing::warn!("simulator flash not saved: {e}");
        }
    }

    /// A device transmission has left the line: the bytes the host receives.
    fn deliver(&mut self, d: DeviceTx, host_baud: Option<u32>) -> Option<Delivery> {
        self.log.push(WireFrame {
            start: d.start,
            end: d.end,
            from_host: false,
            dev_id: Some(d.dev_id),
            bytes: d.bytes,
            collided: d.collided,
        });
        let mut bytes = d.bytes;
        if d.collided {
            self.stats.collided_replies += 1;
            if self.garbage_until.is_some_and(|g| d.start < g) {
                return None;
            }
            self.garbage_until = Some(d.end);
            bytes = collide(&bytes, &noise_frame(&mut self.rng));
        } else if host_baud != Some(d.baud) {
            self.stats.baud_mismatches += 1;
            bytes = misframed(&bytes);
        } else if self.faults.corrupt(&mut bytes, &mut self.rng) {
            self.stats.corrupted_replies += 1;
        } else if d.spontaneous {
            self.stats.announcements += 1;
        } else {
            self.stats.replies += 1;
        }
        if self.unplugged {
            return None;
        }
        Some(Delivery { due: d.end, bytes })
    }

    /// Counters and line busy time as of `now`.
    pub(crate) fn stats(&self, now: Instant) -> SimStats {
        let dec = self.decoder.stats();
        self.host.fill(SimStats {
            at: now,
            busy: self.wire.busy_until(now),
            crc_errors: dec.crc_errors + self.corrupted_host_frames,
            skipped_bytes: dec.skipped_bytes,
            unplugged: self.unplugged,
            ..self.stats
        })
    }

    /// Every device's state, physics run up to `now`.
    pub(crate) fn views(&mut self, now: Instant) -> Vec<DeviceView> {
        self.devices
            .iter_mut()
            .map(|d| {
                d.advance_to(now);
                d.view()
            })
            .collect()
    }

    pub(crate) fn frame_log(&self) -> Vec<WireFrame> {
        self.log.snapshot()
    }

    pub(crate) fn clear_frame_log(&mut self) {
        self.log.clear();
    }

    /// The line was unplugged (in-flight frames are lost) or plugged back.
    pub(crate) fn set_unplugged(&mut self, unplugged: bool) {
        self.unplugged = unplugged;
        if unplugged {
            self.wire.clear_in_flight();
        }
        self.decoder.clear();
    }
}

#[cfg(test)]
#[path = "engine_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "firmware_tests.rs"]
mod firmware_tests;
