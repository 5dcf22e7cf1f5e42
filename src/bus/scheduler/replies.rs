//! What comes back from the wire and the port: replies (asked for or not),
//! missed replies, the port lost and reopened. Each updates the line model,
//! the registry and the setpoints waiting, and says what the owner must do
//! with the setpoint store (the scheduler only reads it).

use std::time::{Duration, Instant};

use crate::bus::config::StartPolicy;
use crate::bus::events::BusEvent;
use crate::bus::packets::PacketMark;
use crate::bus::registry::ReplyEffect;
use crate::bus::wire::Want;
use crate::protocol::status::fsm_name;
use crate::protocol::{Reply, ReplyBody};

use super::Scheduler;
use crate::bus::usb::pipeline::Inflight;

impl Scheduler {
    /// The reply a transaction waited for arrived at `at` (it was due at
    /// `due`). A RES from an id nobody has (SET_ID) is not a device yet: the
    /// request renames the old entry itself.
    pub(crate) fn reply(&mut self, reply: &Reply, at: Instant, due: Instant) -> ReplyEffect {
        self.clock.line_free(at);
        self.take_reply(reply, at, due, None)
    }

    /// The reply to a poll written blind (see [`Scheduler::track`]) came
    /// out of the adapter at `at`. The line was held for it by the model
    /// and freed long before it reached the host: nothing to free here.
    pub(crate) fn inflight_reply(
        &mut self,
        reply: &Reply,
        at: Instant,
        inflight: &Inflight,
        packet: Option<PacketMark>,
    ) -> ReplyEffect {
        let change = self
            .pipeline
            .as_mut()
            .and_then(|p| p.replied(inflight, at, packet));
        self.usb_changed(change);
        self.take_reply(reply, at, inflight.window.due, Some(inflight.handed))
    }

    /// `asked`: when the request was written, where it may be before
    /// something the daemon did since (a poll written blind).
    fn take_reply(
        &mut self,
        reply: &Reply,
        at: Instant,
        due: Instant,
        asked: Option<Instant>,
    ) -> ReplyEffect {
        self.clock.observe_reply(due, at);
        self.usb_answered(reply.dev_id, at);
        let feeds =
            self.reg.get(reply.dev_id).is_some() || matches!(reply.body(), ReplyBody::Info01(_));
        if !feeds {
            return ReplyEffect::default();
        }
        let effect = self
            .reg
            .on_reply_asked(reply, at, true, asked, &mut self.events);
        self.after_reply(reply.dev_id, effect);
        effect
    }

    /// A reply nobody waited for: a power-up announcement, or the late reply
    /// of the last read that timed out (which then widens the deadline).
    /// A device that reset forgot its target: what waited for it is stale,
    /// and the owner clears its slot in the store.
    pub(crate) fn unsolicited(&mut self, reply: &Reply, at: Instant) -> ReplyEffect {
        // Behind a pipelining adapter a reply reaches the host long after
        // the wire was free: the model, not the arrival, says when it is.
        if !self.pipelining() {
            self.clock.line_free(at);
        }
        let late = self.late.take(reply.dev_id, reply.index, at);
        if let Some(late) = late {
            self.clock.observe_reply(late.due, at);
        }
        self.usb_answered(reply.dev_id, at);
        let effect = self.reg.on_reply_asked(
            reply,
            at,
            late.is_some(),
            late.map(|l| l.asked_before),
            &mut self.events,
        );
        self.after_reply(reply.dev_id, effect);
        effect
    }

    /// A device that reset or faulted holds no target: what waited to go
    /// to it is stale, and so is a frame planned with it.
    fn after_reply(&mut self, id: u8, effect: ReplyEffect) {
        if effect.reset || effect.faulted {
            self.control.forget(id);
            self.control.clear_prepared();
        }
        if effect.found_enabled {
            self.found_enabled(id);
        }
    }

    /// A joint enabled before the daemon started: reported, and with
    /// `on_start = "disable"` released at the next slot.
    fn found_enabled(&mut self, id: u8) {
        let state = self
            .reg
            .get(id)
            .and_then(|e| e.state.info01)
            .map_or("unknown", |(i, _)| fsm_name(i.fsm));
        let disable = self.on_start == StartPolicy::Disable;
        if disable {
            self.release.insert(id);
        }
        self.events.push(BusEvent::FoundEnabled {
            bus: self.reg.bus().to_string(),
            dev_id: id,
            state,
            on_start: if disable { "disable" } else { "keep" },
        });
    }

    /// The reply to `want`, due at `due`, had not come by `now`: counted
    /// against the device (offline after the configured misses), and the
    /// line is free again.
    pub(crate) fn timed_out(&mut self, want: Want, due: Instant, now: Instant) {
        self.usb_missing(want.dev_id, now);
        self.late.expect(want, due, now);
        self.clock.line_free(now);
        self.reg.on_missed(want.dev_id, &mut self.events);
    }

    /// The reply to `want`, due at `due`, was given up at `now`, before
    /// its deadline, for an e-stop: nothing against the device nor the USB
    /// path (it may still come, and is then taken in as a late one); the
    /// line is free again. The cut-in settles the write as its deadline
    /// would: a look at the port's count after it would hold the line
    /// from that look for the whole time the transaction waited, and the
    /// e-stop with it.
    pub(crate) fn given_up(&mut self, want: Want, due: Instant, now: Instant) {
        self.late.expect(want, due, now);
        self.clock.line_free(now);
        self.exchange_settled();
    }

    /// A poll written blind got no reply by its deadline: missed like any
    /// other, but the line was never held for it beyond the model.
    pub(crate) fn inflight_timed_out(&mut self, inflight: &Inflight, now: Instant) {
        self.usb_missing(inflight.want.dev_id, now);
        self.late
            .expect(inflight.want, inflight.window.due, inflight.handed);
        self.reg.on_missed(inflight.want.dev_id, &mut self.events);
    }

    /// Behind a USB adapter: `dev_id` answered at `at`; a reply of it
    /// missed shortly before was lost on the way.
    fn usb_answered(&mut self, dev_id: u8, at: Instant) {
        let change = self
            .pipeline
            .as_mut()
            .and_then(|p| p.guard_mut().answered(dev_id, at));
        self.usb_changed(change);
    }

    fn usb_missing(&mut self, dev_id: u8, now: Instant) {
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.guard_mut().reply_missing(dev_id, now);
        }
    }

    /// A read that some firmware does not answer (a revision probe) got no
    /// reply by `now`: the line is free again, and the silence says
    /// nothing against the device (it is not a missed poll).
    pub(crate) fn unanswered(&mut self, want: Want, due: Instant, now: Instant) {
        self.late.expect(want, due, now);
        self.clock.line_free(now);
    }

    /// The port opened at `now` (its adapter already set: the quiet spell
    /// waits out what it holds); true when it had been up before (a
    /// reconnect).
    pub(crate) fn link_up(&mut self, now: Instant) -> bool {
        self.clock.line_free(now);
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.reset();
            pipeline.guard_mut().link_up(now);
        }
        self.reopen.opened(now, self.clock.adapter().reply_hold())
    }

    /// Opening the port failed at `now`; returns the wait before the next try.
    pub(crate) fn open_failed(&mut self, now: Instant) -> Duration {
        self.reopen.open_failed(now)
    }

    /// The port was lost at `now`: every device offline, pending setpoints
    /// forgotten (and, while the bus is down, every new write skipped as
    /// stale: see [`Scheduler::next`]). Returns the wait before the first retry.
    pub(crate) fn link_lost(&mut self, now: Instant) -> Duration {
        self.control.clear_prepared();
        self.control.clear_pending();
        if let Some(pipeline) = self.pipeline.as_mut() {
            pipeline.reset();
        }
        self.reg.all_offline(&mut self.events);
        self.reopen.lost(now)
    }

    /// True while the port is believed open.
    pub(crate) fn link_is_up(&self) -> bool {
        self.reopen.is_up()
    }
}
