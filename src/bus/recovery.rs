//! A bus whose port is lost: every device offline, requests and e-stops
//! answered `Down`, the port reopened with backoff (a tty by its path, a
//! handed-in transport probed), and on success the bus resumes by itself.

use std::io;
use std::sync::atomic::Ordering;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use crate::transport::tty::PortNote;

use super::error::BusError;
use super::handle::{BusEvent, LinkState};
use super::owner::Owner;

/// How often a down bus looks at its requests and e-stops.
const DOWN_TICK: Duration = Duration::from_millis(10);
/// First and longest wait between attempts to reopen a lost port.
pub(super) const BACKOFF_FIRST: Duration = Duration::from_millis(20);
const BACKOFF_MAX: Duration = Duration::from_secs(1);
/// How long a freshly opened port is only listened to: devices powered up
/// with the daemon announce themselves (INFO_01) within a few ms, and a
/// frame written meanwhile would collide with their announcements.
const LISTEN_ON_OPEN: Duration = Duration::from_millis(20);

impl Owner {
    pub(super) fn while_down(&mut self) {
        let now = Instant::now();
        self.housekeeping(now);
        if self.estop_pending() {
            self.estop();
        }
        // A setpoint sent while the bus was down is stale when it comes back.
        self.drop_setpoints();
        if now >= self.next_open {
            self.try_open();
            return;
        }
        let wait = DOWN_TICK.min(self.next_open - now);
        match self.requests.recv_timeout(wait) {
            Ok(req) => {
                self.shared.queued.fetch_sub(1, Ordering::Relaxed);
                super::jobs::fail(req, self.down_error());
            }
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => {}
        }
    }

    pub(super) fn try_open(&mut self) {
        match self.link.open() {
            Ok(notes) => {
                self.note_port(notes);
                if self.ever_up {
                    self.link.counters.reconnects += 1;
                }
                self.ever_up = true;
                self.backoff = BACKOFF_FIRST;
                self.link_state = LinkState::Up;
                tracing::info!(bus = %self.cfg.name, path = %self.cfg.path.display(), "bus up");
                self.events.push(BusEvent::BusUp {
                    bus: self.cfg.name.clone(),
                });
                let _ = self.wait_until(Instant::now() + LISTEN_ON_OPEN);
            }
            Err(e) => {
                let retry = self.backoff;
                self.next_open = Instant::now() + retry;
                self.backoff = (self.backoff * 2).min(BACKOFF_MAX);
                self.mark_down(
                    format!("cannot open {}: {e}", self.cfg.path.display()),
                    retry,
                );
            }
        }
        self.publish(Instant::now());
    }

    /// The port failed: the bus is down until it reopens.
    pub(super) fn lost(&mut self, e: io::Error) -> BusError {
        self.link.close();
        self.prepared = None;
        self.reg.all_offline(&mut self.events);
        self.pending.clear();
        self.backoff = BACKOFF_FIRST;
        self.next_open = Instant::now() + BACKOFF_FIRST;
        self.mark_down(format!("port lost: {e}"), BACKOFF_FIRST);
        self.down_error()
    }

    fn mark_down(&mut self, reason: String, retry: Duration) {
        let was_down = matches!(self.link_state, LinkState::Down { .. });
        if !was_down {
            tracing::warn!(bus = %self.cfg.name, %reason, "bus down");
            self.events.push(BusEvent::BusDown {
                bus: self.cfg.name.clone(),
                reason: reason.clone(),
            });
        }
        self.link_state = LinkState::Down {
            reason,
            retry_in_ms: retry.as_millis() as u64,
        };
    }

    pub(super) fn down_error(&self) -> BusError {
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

    /// Logs what opening the port found; an FTDI latency timer also widens
    /// the reply timeout, since it delays every reply by that much.
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
                PortNote::FtdiLatency { ms, fix } => {
                    self.link
                        .clock
                        .add_reply_margin(Duration::from_millis(u64::from(ms)));
                    let text =
                        format!("FTDI latency timer is {ms} ms (delays every reply); fix: {fix}");
                    tracing::warn!(bus = %self.cfg.name, "{text}");
                    text
                }
            };
            self.port_notes.push(text);
        }
    }
}
