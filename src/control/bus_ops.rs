//! What a bus is asked besides motion, as every front-end offers it: a
//! scan, the baud, a device's blocks read now, its parameters written and
//! verified (one device, or every device in one frame where the bus can),
//! flash, a new id. The checks live here (ids in range, an id taken, a
//! device known); REST only translates.

use crate::bus::handle::{WriteAllOutcome, WriteOutcome};
use crate::bus::BusError;
use crate::protocol::{BaudLevel, ConfigParam, InfoBlock, Reply};

use super::error::{ControlError, ControlResult};
use super::joints::{device_id, known_device};
use super::state::Control;

/// Ids one scan request covers: each bus request must finish within the
/// handle's request timeout (a full-range scan at a low baud would not;
/// 16 absent ids at 19200 baud take well under it), and other requests
/// get the wire between chunks.
const SCAN_CHUNK: u8 = 16;

impl Control {
    /// Polls INFO_01 of every id in `first..=last`; the ids that answered
    /// (they join the bus and are polled from then on).
    pub(crate) async fn scan(&self, bus: &str, first: u8, last: u8) -> ControlResult<Vec<u8>> {
        let handle = self.bus(bus)?;
        let mut found = Vec::new();
        for chunk_first in (first..=last).step_by(usize::from(SCAN_CHUNK)) {
            let chunk_last = chunk_first.saturating_add(SCAN_CHUNK - 1).min(last);
            found.extend(handle.scan(chunk_first, chunk_last).await?);
        }
        Ok(found)
    }

    /// The new baud to every known device (each confirms), then the port.
    pub(crate) async fn set_baud(&self, bus: &str, level: BaudLevel) -> ControlResult<()> {
        self.bus(bus)?.set_baud(level.baud()).await?;
        Ok(())
    }

    /// Block `block` of a known device, read now.
    pub(crate) async fn read_info(
        &self,
        bus: &str,
        id: u8,
        block: InfoBlock,
    ) -> ControlResult<Reply> {
        let handle = self.bus(bus)?;
        known_device(&handle.snapshot(), id)?;
        Ok(handle.read_info(id, block).await?)
    }

    /// One parameter written to device `id` and verified: the bus's answer
    /// kept whole (a write sent and not confirmed, `Unverified`, is not a
    /// write refused), inside the core's refusal of an unknown bus.
    pub(crate) async fn write_config(
        &self,
        bus: &str,
        id: u8,
        config: ConfigParam,
    ) -> ControlResult<Result<WriteOutcome, BusError>> {
        Ok(self.bus(bus)?.write_config(id, config).await)
    }

    /// One parameter to every device of `ids`: in one frame to 0xFF where
    /// the bus can (every device on rev 2.0.8, none that would hear it
    /// unasked), one write each otherwise; each device answers for itself.
    pub(crate) async fn write_all(
        &self,
        bus: &str,
        ids: Vec<u8>,
        config: ConfigParam,
    ) -> ControlResult<WriteAllOutcome> {
        Ok(self.bus(bus)?.write_all(ids, config).await?)
    }

    /// A known device's RAM parameters stored to flash.
    pub(crate) async fn persist(&self, bus: &str, id: u8) -> ControlResult<WriteOutcome> {
        let handle = self.bus(bus)?;
        known_device(&handle.snapshot(), id)?;
        Ok(handle.write_flash(id).await?)
    }

    /// A known device's id changed to `new_id` (asked as given): not its
    /// own, not one taken on the bus. The new id and how it was confirmed.
    pub(crate) async fn change_id(
        &self,
        bus: &str,
        id: u8,
        new_id: i64,
    ) -> ControlResult<(u8, WriteOutcome)> {
        let handle = self.bus(bus)?;
        let new_id = device_id("new_id", new_id)?;
        let snap = handle.snapshot();
        known_device(&snap, id)?;
        if new_id == id {
            return Err(ControlError::invalid(
                "new_id",
                format!("device already has id {id}"),
            ));
        }
        if snap.devices.contains_key(&new_id) {
            return Err(ControlError::conflict(
                "id-in-use",
                "Id already in use",
                format!(
                    "id {new_id} is taken on bus {}: two devices with one id collide",
                    snap.name
                ),
            )
            .with_field("new_id"));
        }
        Ok((new_id, handle.set_id(id, new_id).await?))
    }
}
