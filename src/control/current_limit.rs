//! A joint's current limit (MAX_CUR) read from INFO_04 and written back
//! with a read-back, for the routines that lower it for a while (homing
//! pushes into a hard stop, a grasp holds an object) and must give back
//! the previous one however they end.

use crate::bus::BusHandle;
use crate::protocol::{ConfigParam, InfoBlock, ReplyBody};

/// Writes of the previous limit before giving up on it.
const RESTORE_TRIES: usize = 3;

/// The joint's current limit (raw, Q15) as INFO_04 reports it.
pub(crate) async fn read(bus: &BusHandle, id: u8) -> Result<u16, String> {
    let reply = bus
        .read_info(id, InfoBlock::Info04)
        .await
        .map_err(|e| format!("could not read the current limit (INFO_04): {e}"))?;
    match reply.body() {
        ReplyBody::Info04(i) => Ok(i.max_current),
        _ => Err("the joint answered INFO_04 with another block".into()),
    }
}

/// Writes `previous` back, then reads it back: true only when the
/// read-back shows it. A few tries; a write whose confirmation was lost
/// may still have taken, which the read-back tells. `who` names the
/// routine in the log.
pub(crate) async fn restore(bus: &BusHandle, id: u8, previous: u16, who: &str) -> bool {
    for attempt in 1..=RESTORE_TRIES {
        if let Err(e) = bus.write_config(id, ConfigParam::MaxCur(previous)).await {
            tracing::warn!(bus = bus.name(), id, attempt, error = %e,
                "{who}: writing the previous current limit back failed");
        }
        match read(bus, id).await {
            Ok(raw) if raw == previous => return true,
            Ok(raw) => tracing::warn!(
                bus = bus.name(),
                id,
                attempt,
                read_back = raw,
                previous,
                "{who}: the current limit read back is not the previous one"
            ),
            Err(why) => tracing::warn!(bus = bus.name(), id, attempt, "{who}: {why}"),
        }
    }
    false
}
