//! Publication: rolls the rate window and publishes the snapshot (then the
//! events, so a subscriber who hears of a change finds it in the snapshot).

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Instant, SystemTime};

use crate::bus::handle::{BusEvent, BusSnapshot};

use super::Ctx;

impl Ctx {
    /// Rolls the rate window and publishes the snapshot when due (or at
    /// once when something happened that subscribers should see).
    pub(crate) fn housekeeping(&mut self, now: Instant) {
        if let Some(window) = self.stats.roll(now, &self.link.counters) {
            self.sched.registry_mut().roll_rates(window);
            let timeout = self.sched.clock().reply_timeout(now);
            self.stats.set_reply_timeout(timeout);
            self.stats.set_wake_lead(self.link.wake_lateness());
            self.stats.set_reply_lag(self.reply_lag.lag());
        }
        if self.stats.due(now) || self.sched.has_events() {
            self.publish(now);
        }
    }

    /// Publishes the snapshot, then the events (so a subscriber who hears
    /// of a change finds it in the snapshot).
    pub(crate) fn publish(&mut self, now: Instant) {
        let snapshot = BusSnapshot {
            name: self.cfg.name.clone(),
            path: self.cfg.path.display().to_string(),
            baud: self.link.baud(),
            link: self.link_state.clone(),
            devices: self.sched.registry().device_states(),
            counters: self.link.counters.clone(),
            queue_depth: self.shared.queued.load(Ordering::Relaxed),
            polls_in_flight: self.sched.in_flight(),
            published_at: now,
            published_wall: SystemTime::now(),
            rates: self.stats.rates().clone(),
            latency: self.stats.latency().clone(),
            port_notes: self
                .thread_notes
                .iter()
                .chain(&self.port_notes)
                .cloned()
                .collect(),
            adapter: self.sched.clock().adapter().to_string(),
            transaction_us: self.sched.clock().transaction_time().as_micros() as u64,
            usb_pipeline: self.sched.usb_view(now),
        };
        self.shared.snapshot.send_replace(Arc::new(snapshot));
        for event in self.sched.drain_events() {
            log_event(&self.cfg.name, &event);
            self.shared.emit(event);
        }
        self.stats.published(now);
    }
}

/// The events an operator must find in the log, once each (here, where
/// they are published, not on the reply path that detected them).
fn log_event(bus: &str, event: &BusEvent) {
    match event {
        BusEvent::DeviceReset {
            dev_id,
            seen,
            state_before,
            state,
            ..
        } => tracing::warn!(
            bus,
            dev_id,
            "device {dev_id} reset (power cut or reboot): {} ({state_before} -> {state}); \
             it is disabled and its targets are forgotten",
            seen.name()
        ),
        BusEvent::FoundEnabled {
            dev_id,
            state,
            on_start,
            ..
        } => tracing::warn!(
            bus,
            dev_id,
            "device {dev_id} found enabled at start ({state}), its target unknown; \
             on_start = \"{on_start}\""
        ),
        BusEvent::MoveAborted {
            move_id, reason, ..
        } => tracing::warn!(bus, move_id, "move {move_id} aborted: {reason}"),
        _ => {}
    }
}
