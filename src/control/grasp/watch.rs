//! What a grasp's finger watches of its joint: fresh INFO_02 samples (and
//! its smoothed current), another command taking the joint over, and
//! anything that ends its part (an e-stop, its epoch moving on, the joint
//! offline, faulted or disabled).

use std::time::Instant;

use tokio::sync::{broadcast, watch};

use super::detect::Sample;
use super::plan::Finger;
use crate::bus::authority::Revoked;
use crate::bus::handle::{BusEvent, DeviceState};
use crate::bus::{BusSnapshot, Setpoint};
use crate::control::device::{firmware_of, is_enabled};
use crate::protocol::status::{active_fault, fault_name, fsm};
use crate::protocol::units;

/// Weight of the newest sample in the reported q current.
const CURRENT_SMOOTHING: f64 = 0.3;

/// The finger's watch over its joint.
pub(crate) struct Watch {
    pub snaps: watch::Receiver<std::sync::Arc<BusSnapshot>>,
    events: broadcast::Receiver<BusEvent>,
    last_sample: Option<Instant>,
    /// The finger's latest target, and whether the wire has carried it
    /// (from then on another target there means another command).
    sent: Setpoint,
    seen_sent: bool,
    /// The q current, smoothed over a few samples, A.
    pub current: Option<f64>,
}

impl Watch {
    pub(crate) fn new(f: &Finger) -> Self {
        Self {
            snaps: f.bus.watch(),
            events: f.bus.events(),
            last_sample: None,
            sent: Setpoint {
                pos_ref: 0,
                spd_ref: 0,
            },
            seen_sent: false,
            current: None,
        }
    }

    /// The finger sent `sp`: from when the wire carries it, another target
    /// there means another command took the joint.
    pub(crate) fn sent(&mut self, sp: Setpoint) {
        self.sent = sp;
        self.seen_sent = false;
    }

    /// The finger's latest target.
    pub(crate) fn last_sent(&self) -> Setpoint {
        self.sent
    }
}

/// A new INFO_02 of the joint since the last one, as a sample (and the
/// smoothed current written to the finger's view).
pub(crate) fn fresh_sample(
    dev: Option<&DeviceState>,
    w: &mut Watch,
    started: Instant,
) -> Option<Sample> {
    let dev = dev?;
    let (info, at) = dev.info02.as_ref().map(|(i, at)| (*i, *at))?;
    if at < started || w.last_sample.is_some_and(|last| at <= last) {
        return None;
    }
    w.last_sample = Some(at);
    let fw = firmware_of(dev);
    let current = units::current_a(info.q_cur);
    let smoothed = w.current.map_or(current.abs(), |c| {
        c + CURRENT_SMOOTHING * (current.abs() - c)
    });
    w.current = Some(smoothed);
    Some(Sample {
        t: at.duration_since(started),
        deg: units::angle_deg(info.angle),
        speed_dps: units::output_deg_per_s(info.speed_rpm(fw)),
        current_a: current,
    })
}

/// Another command replaced the grasp's target on the wire.
pub(crate) fn taken_over(dev: Option<&DeviceState>, w: &mut Watch) -> Option<String> {
    let on_wire = dev?.target_sent?;
    if on_wire == w.sent {
        w.seen_sent = true;
        return None;
    }
    w.seen_sent
        .then(|| "another command took the joint".to_string())
}

/// An e-stop, the epoch moved on, offline, faulted or disabled.
pub(crate) fn unfit(f: &Finger, w: &mut Watch) -> Result<(), String> {
    loop {
        match w.events.try_recv() {
            Ok(BusEvent::Estop { bus }) if bus == f.bus.name() => return Err("e-stop".into()),
            Ok(_) | Err(broadcast::error::TryRecvError::Lagged(_)) => continue,
            Err(_) => break,
        }
    }
    if !f.bus.authority().admits(f.id, f.epoch) {
        return Err(match f.bus.authority().last_revoked(f.id) {
            Some(Revoked::Estopped) => "e-stop".to_string(),
            Some(why) => format!("the joint's commands were revoked ({})", why.name()),
            None => "the joint is no longer enabled".to_string(),
        });
    }
    let snap = f.bus.snapshot();
    let Some(dev) = snap.devices.get(&f.id).filter(|d| d.online) else {
        return Err("the joint went offline".into());
    };
    if let Some((info, _)) = &dev.info01 {
        if info.fsm == fsm::FAULT || active_fault(info.err_code) != 0 {
            return Err(format!(
                "the joint faulted ({})",
                fault_name(active_fault(info.err_code))
            ));
        }
        if !is_enabled(info) {
            return Err(format!(
                "the joint was disabled ({})",
                dev.disabled_reason.map_or("disabled", |r| r.name())
            ));
        }
    }
    Ok(())
}
