//! Faults injected into a running simulated bus: on the line, on one
//! device, or cleared all at once.

use std::time::{Duration, Instant};

use super::Engine;
use crate::sim::device::Device;
use crate::sim::faults::{Fault, LineFaults};

impl Engine {
    /// Applies a device or line fault (unplugging itself is the runner's job).
    pub(crate) fn inject(&mut self, fault: Fault, now: Instant) {
        match fault {
            Fault::CorruptRate(r) => self.faults.corrupt_rate = r.clamp(0.0, 1.0),
            Fault::DropReplies { dev_id, rate } => self.faults.set_drop(dev_id, rate),
            Fault::ExtraTurnaround(d) => self.faults.extra_turnaround = d,
            Fault::MissControl { dev_id, count } => {
                self.faults.miss_control.insert(dev_id, count);
            }
            Fault::Stall { dev_id, at_deg } => self.each(dev_id, |d| d.set_obstacle(at_deg, now)),
            Fault::Object {
                dev_id,
                at_deg,
                nm_per_deg,
            } => self.each(dev_id, |d| d.set_object(at_deg, nm_per_deg, now)),
            Fault::RemoveObject { dev_id } => self.each(dev_id, |d| d.remove_object(now)),
            Fault::PowerCycle { dev_id } => self.each(dev_id, |d| d.power_up(now, Duration::ZERO)),
            Fault::UnderVoltage { dev_id, on } => {
                self.each(dev_id, |d| d.set_under_voltage(on, now))
            }
            Fault::Echo(on) => self.echo = on,
            Fault::Noise(every) => {
                self.faults.noise = every.filter(|e| !e.is_zero()).map(|e| (e, now + e));
            }
            Fault::ClearAll => {
                self.faults = LineFaults::default();
                self.echo = false;
                for d in &mut self.devices {
                    d.clear_obstacle(now);
                    d.remove_object(now);
                    d.set_under_voltage(false, now);
                }
            }
            Fault::Unplug | Fault::Replug | Fault::WriteDelay(_) | Fault::StuckCount(_) => {}
        }
    }

    fn each(&mut self, id: u8, f: impl FnMut(&mut Device)) {
        self.devices.iter_mut().filter(|d| d.id == id).for_each(f);
    }
}
