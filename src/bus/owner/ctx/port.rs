//! A bus whose port is lost: every device offline, requests and e-stops
//! answered `Down`, the port reopened with backoff (a tty by its path, a
//! handed-in transport probed), and on success the bus resumes by itself.

use std::io;
use std::sync::atomic::Ordering;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use crate::bus::config::AdapterSetting;
use crate::bus::error::BusError;
use crate::bus::handle::{BusEvent, LinkState};
use crate::transport::adapter::{AdapterInfo, AdapterModel};
use crate::transport::tty::PortNote;

use super::Ctx;

/// How often a down bus looks at its requests and e-stops.
const DOWN_TICK: Duration = Duration::from_millis(10);

impl Ctx {
    /// A down bus: reopens the port at `open_at`, failing requests meanwhile.
    pub(crate) fn while_down(&mut self, now: Instant, open_at: Instant) {
        self.housekeeping(now);
        // Taken while the port was up, its slot never came: it fails like
        // every request that meets a down bus.
        if let Some(req) = self.held.take() {
            req.fail(self.down_error());
        }
        if now >= open_at {
            self.try_open();
            return;
        }
        let wait = DOWN_TICK.min(open_at - now);
        match self.requests.recv_timeout(wait) {
            Ok(req) => {
                self.shared.queued.fetch_sub(1, Ordering::Relaxed);
                req.fail(self.down_error());
            }
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => {}
        }
    }

    /// Opens the port; the scheduler then listens a while before writing.
    pub(crate) fn try_open(&mut self) {
        match self.link.open() {
            Ok(notes) => {
                self.note_port(notes);
                let confirms = self.cfg.timing.usb_confirm && self.link.unsent().is_some();
                self.sched.set_port_confirms(confirms);
                if self.sched.link_up(Instant::now()) {
                    self.link.counters.reconnects += 1;
                }
                self.link_state = LinkState::Up;
                self.ever_up = true;
                tracing::info!(bus = %self.cfg.name, path = %self.cfg.path.display(), "bus up");
                self.sched.push_event(BusEvent::BusUp {
                    bus: self.cfg.name.clone(),
                });
            }
            Err(e) => {
                let retry = self.sched.open_failed(Instant::now());
                self.mark_down(
                    format!("cannot open {}: {e}", self.cfg.path.display()),
                    retry,
                );
            }
        }
        self.publish(Instant::now());
    }

    /// The port failed: the bus is down until it reopens.
    pub(crate) fn lost(&mut self, e: io::Error) -> BusError {
        self.link.close();
        self.abort_moves("the bus went down");
        let retry = self.sched.link_lost(Instant::now());
        self.mark_down(format!("port lost: {e}"), retry);
        self.down_error()
    }

    fn mark_down(&mut self, reason: String, retry: Duration) {
        let was_down = matches!(self.link_state, LinkState::Down { .. });
        if !was_down {
            tracing::warn!(bus = %self.cfg.name, %reason, "bus down");
            self.sched.push_event(BusEvent::BusDown {
                bus: self.cfg.name.clone(),
                reason: reason.clone(),
            });
        }
        self.link_state = LinkState::Down {
            reason,
            retry_in_ms: retry.as_millis() as u64,
        };
    }

    pub(crate) fn down_error(&self) -> BusError {
        let reason = match &self.link_state {
            LinkState::Down { reason, .. } => reason.clone(),
            LinkState::Opening => "port not open yet".into(),
            LinkState::Up => "port not open".into(),
        };
        BusError::Down {
            bus: self.cfg.name.clone(),
            reason,
        }
    }

    /// Logs what opening the port found; the adapter's timing goes to the
    /// scheduler (reply deadlines follow it).
    fn note_port(&mut self, notes: Vec<PortNote>) {
        self.port_notes.clear();
        for note in notes {
            let text = match note {
                PortNote::IoctlUnsupported { what, error } => {
                    tracing::info!(bus = %self.cfg.name, "{what} not set ({error}); normal on a pty");
                    format!("{what} not supported: {error}")
                }
                PortNote::Rs485(text) => {
                    tracing::info!(bus = %self.cfg.name, "{text}");
                    text
                }
                PortNote::Adapter(info) => self.take_adapter(&info),
            };
            self.port_notes.push(text);
        }
    }

    /// The adapter the bus plans for: the config's, or the one sysfs shows.
    /// An FTDI timer above 1 ms is said aloud with its cost and its fix.
    fn take_adapter(&mut self, info: &AdapterInfo) -> String {
        let (model, why) = match self.cfg.adapter {
            AdapterSetting::Fixed(m) => {
                (m, format!("set in the config (sysfs: {})", info.found_by))
            }
            AdapterSetting::Auto => (info.model, format!("detected: {}", info.found_by)),
        };
        self.sched.set_adapter(model);
        self.link.packets.set_payload(model.packet_payload());
        self.adapter_info = Some(AdapterInfo {
            model,
            found_by: why.clone(),
            ..info.clone()
        });
        let mut text = format!("adapter {model} ({why})");
        let mut warn = false;
        if let Some(timer) = model
            .latency_timer()
            .filter(|t| *t > Duration::from_millis(1))
        {
            text = format!("{text}: {}", self.timer_cost(model, timer));
            warn = true;
        }
        // A simulator behind the pty that says when its adapter model took
        // each write (as a driver's output count does) makes writes safe.
        let counted = self.cfg.timing.usb_confirm && self.link.unsent().is_some();
        if model.is_latent() && info.tty_without_usb && !counted {
            text = format!(
                "{text}. No USB device is behind this tty: polls are written without waiting \
                 for their replies, each timed to reach the wire within a USB frame of its \
                 write, and a pty or UART path that holds a write longer puts two on the wire \
                 back to back (collisions: CRC errors, skipped bytes). Set adapter = \"native\" \
                 unless this path has a USB adapter's timing"
            );
            warn = true;
        }
        if warn {
            tracing::warn!(bus = %self.cfg.name, "{text}");
        } else {
            tracing::info!(bus = %self.cfg.name, "{text}");
        }
        text
    }

    /// What a latency timer above 1 ms costs each transaction on this bus,
    /// against the same adapter at 1 ms, and how to set it.
    fn timer_cost(&self, model: AdapterModel, timer: Duration) -> String {
        let with_1ms = match model {
            AdapterModel::Ft232h { .. } => AdapterModel::Ft232h { latency_ms: 1 },
            _ => AdapterModel::Ftdi { latency_ms: 1 },
        };
        let now = self.sched.clock().transaction_time();
        let fast = self.sched.clock().transaction_time_with(with_1ms);
        let speedup = now.as_secs_f64() / fast.as_secs_f64().max(1e-6);
        let name = self
            .cfg
            .path
            .file_name()
            .map_or_else(|| "ttyUSB0".into(), |n| n.to_string_lossy().into_owned());
        format!(
            "its latency timer holds every reply {} ms. Polls keep their rate once they are \
             pipelined (after the first replies show the USB frame clock), but each telemetry \
             sample reaches the host that much older, and each one-shot transaction (enable, a \
             config read or write) takes {:.1} ms; at 1 ms it would take {:.1} ms ({speedup:.1}x \
             faster). Fix: echo 1 | sudo tee /sys/bus/usb-serial/devices/{name}/latency_timer \
             (or the udev rule in deploy/)",
            timer.as_millis(),
            now.as_secs_f64() * 1e3,
            fast.as_secs_f64() * 1e3,
        )
    }
}

impl Ctx {
    /// The port's speed now.
    pub(crate) fn baud(&self) -> u32 {
        self.link.baud()
    }

    /// How long past its modelled time a reply is waited for, as configured.
    pub(crate) fn reply_margin_us(&self) -> u64 {
        self.cfg.timing.reply_margin_us
    }

    /// The port's path as configured.
    pub(crate) fn path(&self) -> &std::path::Path {
        &self.cfg.path
    }

    /// The adapter the bus plans for, once the port reported one.
    pub(crate) fn adapter_info(&self) -> Option<&AdapterInfo> {
        self.adapter_info.as_ref()
    }

    /// What opening the port reported.
    pub(crate) fn port_notes(&self) -> &[String] {
        &self.port_notes
    }

    /// Runs `f` on the open port (a lent port: [`crate::bus::loan`]).
    pub(crate) fn with_port(&mut self, f: impl FnOnce(&mut dyn crate::transport::Transport)) {
        self.link.with_port(f);
    }

    /// The line was used by someone else: it is modelled free from `now`,
    /// the frame clock learnt again, and the scheduler listens before writing.
    pub(crate) fn relisten(&mut self, now: Instant) {
        self.sched.link_up(now);
    }

    pub(crate) fn switch_port(&mut self, baud: u32) -> Result<(), BusError> {
        self.wait_until(self.sched.clock().free_at())?;
        self.link.set_baud(baud).map_err(|e| self.lost(e))?;
        self.cfg.baud = baud;
        self.sched.set_baud(baud);
        Ok(())
    }

    /// Forgets every setpoint, in the store and on their way (e-stop,
    /// shutdown), and stops every move on this bus first.
    pub(crate) fn drop_all_setpoints(&mut self) {
        self.abort_moves("every joint disabled (e-stop or shutdown)");
        self.shared.setpoints.clear(None);
        self.sched.drop_setpoints(&self.shared.setpoints);
    }

    /// Aborts every move a joint of this bus follows, and says so.
    pub(crate) fn abort_moves(&mut self, reason: &str) {
        for move_id in self.shared.motion.abort_all(reason) {
            self.sched.push_event(BusEvent::MoveAborted {
                bus: self.cfg.name.clone(),
                move_id,
                reason: reason.to_string(),
            });
        }
    }

    /// True while the port is open.
    pub(crate) fn link_is_up(&self) -> bool {
        self.link.is_up()
    }
}
