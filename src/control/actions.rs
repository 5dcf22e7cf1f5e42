//! One-shot actions on joints, as every front-end offers them: enable,
//! disable, mode, jog, re-zero and targets, for one joint or a group of
//! one bus, and the e-stop of some buses or all. The checks live here
//! (known joints, each named once, a mode the joint's firmware has, a jog
//! or a target only while enabled), then the bus is asked: REST, WebSocket
//! and ROS 2 only translate.

use std::sync::Arc;

use crate::bus::{BusSnapshot, Setpoint, Targets};
use crate::protocol::params::Revision;
use crate::protocol::{CtrlMode, JogDir};

use super::error::{ControlError, ControlResult};
use super::estop::{self, EstopResult};
use super::joints::{device_id, known_device};
use super::revision::require_revision;
use super::state::Control;
use super::targets::{ensure_enabled, setpoint, wait_on_wire, TargetRequest};

/// Targets stored in one write, and whether they reached the wire.
#[derive(Debug)]
pub(crate) struct TargetsSet {
    /// The bus as the targets were checked against.
    pub snapshot: Arc<BusSnapshot>,
    /// Sequence number of the write in the bus's setpoint store.
    pub seq: u64,
    /// The frame carrying them was written to the port within the wait.
    pub on_wire: bool,
    pub setpoints: Vec<(u8, Setpoint)>,
}

impl Control {
    /// Device `id` of a known bus: 404 for the bus first, then 422 for an
    /// id outside the protocol's range.
    pub(crate) fn joint_id(&self, bus: &str, id: i64) -> ControlResult<u8> {
        self.bus(bus)?;
        device_id("id", id)
    }

    /// The ids of a group action, each a device id named once and known
    /// on the bus; `None`: every device of the bus.
    pub(crate) fn group_ids(
        &self,
        bus: &str,
        ids: Option<Vec<i64>>,
    ) -> ControlResult<Option<Vec<u8>>> {
        let snap = self.bus(bus)?.snapshot();
        let Some(ids) = ids else { return Ok(None) };
        if ids.is_empty() {
            return Err(ControlError::invalid(
                "ids",
                "ids is empty: omit it to address every device",
            ));
        }
        let mut out = Vec::with_capacity(ids.len());
        for (i, id) in ids.into_iter().enumerate() {
            let id = device_id(&format!("ids[{i}]"), id)?;
            if out.contains(&id) {
                return Err(ControlError::invalid(
                    &format!("ids[{i}]"),
                    format!("joint {id} appears twice"),
                ));
            }
            known_device(&snap, id)?;
            out.push(id);
        }
        Ok(Some(out))
    }

    /// Enables the joints (`None`: every joint of the bus) and waits until
    /// each reports enabled.
    pub(crate) async fn enable(&self, bus: &str, ids: Option<Vec<u8>>) -> ControlResult<()> {
        self.known(bus, ids.as_deref())?;
        self.bus(bus)?.enable(targets_of(ids)).await?;
        Ok(())
    }

    /// Disables the joints (`None`: every joint of the bus).
    pub(crate) async fn disable(&self, bus: &str, ids: Option<Vec<u8>>) -> ControlResult<()> {
        self.known(bus, ids.as_deref())?;
        self.bus(bus)?.disable(targets_of(ids)).await?;
        Ok(())
    }

    /// Switches the joints (`None`: every joint of the bus) to `mode`,
    /// every one checked before any is switched (current mode needs rev
    /// 2.0.8 firmware); the ids switched.
    pub(crate) async fn set_mode(
        &self,
        bus: &str,
        ids: Option<Vec<u8>>,
        mode: CtrlMode,
    ) -> ControlResult<Vec<u8>> {
        let handle = self.bus(bus)?;
        let snap = handle.snapshot();
        let each: Vec<u8> = ids.unwrap_or_else(|| snap.devices.keys().copied().collect());
        for &id in &each {
            let dev = known_device(&snap, id)?;
            if mode == CtrlMode::Current {
                require_revision("mode", "current mode", Revision::V2_0_8, id, dev)?;
            }
        }
        for &id in &each {
            handle.set_mode(id, mode).await?;
        }
        Ok(each)
    }

    /// Jogs an enabled joint (`cw` +5°, `ccw` −3°; it re-zeroes after).
    pub(crate) async fn jog(&self, bus: &str, id: u8, dir: JogDir) -> ControlResult<()> {
        let handle = self.bus(bus)?;
        let snap = handle.snapshot();
        ensure_enabled(handle, known_device(&snap, id)?, "a jog").await?;
        handle.jog(id, dir).await?;
        Ok(())
    }

    /// Makes where the joint stands its new 0°.
    pub(crate) async fn rezero(&self, bus: &str, id: u8) -> ControlResult<()> {
        let handle = self.bus(bus)?;
        known_device(&handle.snapshot(), id)?;
        handle.rezero(id).await?;
        Ok(())
    }

    /// Checks every target (soft limits, the joint's state: one bad target
    /// refuses them all), then stores them in one write and waits (briefly)
    /// for the wire. `targets`: (device id as asked, the target, the
    /// request member it came from, e.g. `targets[2].`).
    pub(crate) async fn set_targets(
        &self,
        bus: &str,
        targets: &[(i64, TargetRequest, String)],
    ) -> ControlResult<TargetsSet> {
        let handle = self.bus(bus)?;
        if targets.is_empty() {
            return Err(ControlError::invalid("targets", "targets is empty"));
        }
        let snapshot = handle.snapshot();
        let mut setpoints: Vec<(u8, Setpoint)> = Vec::with_capacity(targets.len());
        for (id, req, field) in targets {
            let id = device_id(&format!("{field}id"), *id)?;
            if setpoints.iter().any(|(seen, _)| *seen == id) {
                return Err(ControlError::invalid(
                    &format!("{field}id"),
                    format!("joint {id} appears twice"),
                ));
            }
            let dev = known_device(&snapshot, id)?;
            let limits = self.limits(bus, id);
            let cal = self.calibration(bus, id);
            setpoints.push((id, setpoint(dev, &limits, &cal, req, field)?));
        }
        for (id, _) in &setpoints {
            if let Some(dev) = snapshot.devices.get(id) {
                ensure_enabled(handle, dev, "a target").await?;
            }
        }
        let seq = handle.set_targets(&setpoints);
        let on_wire = wait_on_wire(handle, seq).await;
        Ok(TargetsSet {
            snapshot,
            seq,
            on_wire,
            setpoints,
        })
    }

    /// The e-stop of every bus at once.
    pub(crate) async fn estop_all(&self) -> EstopResult {
        estop::stop(self.buses().cloned().collect()).await
    }

    /// The e-stop of the buses named (each once; unknown names: 404 before
    /// any bus is stopped).
    pub(crate) async fn estop_buses(&self, names: &[&str]) -> ControlResult<EstopResult> {
        let buses = names
            .iter()
            .map(|n| self.bus(n).cloned())
            .collect::<ControlResult<Vec<_>>>()?;
        Ok(estop::stop(buses).await)
    }

    /// Each id known on the bus (the bus itself for `None`).
    fn known(&self, bus: &str, ids: Option<&[u8]>) -> ControlResult<()> {
        let snap = self.bus(bus)?.snapshot();
        for &id in ids.unwrap_or_default() {
            known_device(&snap, id)?;
        }
        Ok(())
    }
}

fn targets_of(ids: Option<Vec<u8>>) -> Targets {
    ids.map_or(Targets::All, Targets::Ids)
}
