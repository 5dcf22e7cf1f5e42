//! The emergency stop: disable frames ahead of everything queued, then a
//! read-back of every online device. A device that still drives its motor
//! (it missed every disable, e.g. to noise on its stub) is disabled again
//! and read once more; what could not be confirmed is reported, never
//! assumed.

use std::time::Instant;

use crate::protocol::reply::fsm;
use crate::protocol::{Command, Control, ALL_DEVICES};

use super::error::BusError;
use super::handle::{BusEvent, EstopReport};
use super::owner::Owner;

/// States in which a joint module powers its motor (SPEC §5 fsm; rev 2.0.8's
/// `6 start` included).
fn drives_motor(state: u8) -> bool {
    const START: u8 = 6;
    matches!(state, fsm::ALIGN | START | fsm::RUN)
}

/// What reading a device back after the stop found.
enum ReadBack {
    Stopped,
    Driving,
    NoAnswer,
}

impl Owner {
    /// Disables every device ahead of everything queued (SPEC errata 3:
    /// standard control frames, `0xFF` first, then each known device), then
    /// confirms it device by device.
    pub(super) fn estop(&mut self, generation: u64) {
        let called = self
            .shared
            .estop_called
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        let sent = self.disable_everything();
        let preempted = self.fail_queued(&BusError::Preempted);
        let result = sent.map(|(frames_sent, handed)| {
            let mut report = EstopReport {
                bus: self.cfg.name.clone(),
                frames_sent,
                preempted_requests: preempted,
                latency_us: called.map_or(0, |c| {
                    handed.saturating_duration_since(c).as_micros() as u64
                }),
                ..EstopReport::default()
            };
            self.confirm_stopped(&mut report);
            report
        });
        if let Ok(r) = &result {
            if !r.still_enabled.is_empty() {
                tracing::error!(bus = %self.cfg.name, "e-stop: {:?} still enabled after a second disable", r.still_enabled);
            }
        }
        self.sched.push_event(BusEvent::Estop {
            bus: self.cfg.name.clone(),
        });
        self.shared
            .estop_done
            .send_replace((generation, Some(result)));
        self.publish(Instant::now());
    }

    /// Writes the disable frames and forgets every setpoint; returns the
    /// frame count and when they were handed to the port.
    pub(super) fn disable_everything(&mut self) -> Result<(u32, Instant), BusError> {
        self.shared.setpoints.clear(None);
        self.sched.drop_setpoints(&self.shared.setpoints);
        for id in self.sched.registry().ids() {
            self.sched.registry_mut().forget_target(id);
        }
        if !self.link.is_up() {
            return Err(self.down_error());
        }
        // 0xFF, each device, 0xFF again: an e-stop does not wait out a late
        // reply, and one reply can collide with two consecutive host frames
        // (0xFF and device 1's); it cannot reach both ends of the sequence,
        // so every device hears at least one disable.
        let cmds: Vec<Command> = std::iter::once(ALL_DEVICES)
            .chain(self.sched.registry().ids())
            .chain(std::iter::once(ALL_DEVICES))
            .map(|id| Command::Control(Control::disable(id)))
            .collect();
        let handed = Instant::now();
        self.send(&cmds)?;
        Ok((cmds.len() as u32, handed))
    }

    /// Reads every known device back; disables again whoever still drives.
    /// Offline devices, silent ones and those left when a newer e-stop or a
    /// lost port cut the check short are `unconfirmed`.
    fn confirm_stopped(&mut self, report: &mut EstopReport) {
        self.sched.job_start();
        let ids = self.sched.registry().ids();
        for (n, &id) in ids.iter().enumerate() {
            if !self.sched.registry().is_online(id) {
                report.unconfirmed.push(id);
                continue;
            }
            let found = match self.read_back(id) {
                Ok(ReadBack::Driving) => {
                    report.disabled_again.push(id);
                    self.disable_again(id)
                }
                other => other,
            };
            match found {
                Ok(ReadBack::Stopped) => report.confirmed.push(id),
                Ok(ReadBack::Driving) => report.still_enabled.push(id),
                Ok(ReadBack::NoAnswer) => report.unconfirmed.push(id),
                Err(e) => {
                    tracing::warn!(bus = %self.cfg.name, "e-stop read-back cut short: {e}");
                    report.unconfirmed.extend_from_slice(&ids[n..]);
                    break;
                }
            }
        }
    }

    fn disable_again(&mut self, id: u8) -> Result<ReadBack, BusError> {
        self.job_send(&[Command::Control(Control::disable(id))])?;
        self.read_back(id)
    }

    /// INFO_01 with the configured retries; silence is an answer here.
    fn read_back(&mut self, id: u8) -> Result<ReadBack, BusError> {
        match self.read_info01(id) {
            Ok(info) if drives_motor(info.fsm) => Ok(ReadBack::Driving),
            Ok(_) => Ok(ReadBack::Stopped),
            Err(BusError::Timeout { .. }) => Ok(ReadBack::NoAnswer),
            Err(e) => Err(e),
        }
    }
}
