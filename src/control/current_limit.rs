//! A joint's current limit (MAX_CUR) read from INFO_04 and written back
//! with a read-back, for the routines that lower it for a while (homing
//! pushes into a hard stop, a grasp holds an object) and must give back
//! the previous one however they end. A limit that cannot be given back
//! (the joint offline, the bus down) stays owed ([`crate::bus::owed`]):
//! written and read back as soon as the joint answers again, and until
//! then nothing new moves the joint.

use std::time::Duration;

use crate::bus::BusHandle;
use crate::protocol::{ConfigParam, InfoBlock, ReplyBody};

/// Writes of the previous limit before giving up on it for now.
const RESTORE_TRIES: usize = 3;
/// How often an owed limit is tried again while its joint is online.
const OWED_RETRY: Duration = Duration::from_millis(500);

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

/// Writes `previous` back and reads it back ([`write_back`]); when that
/// fails the limit is owed, tried again each time the joint is online
/// until it holds, and `settled` is called then (a view saying so).
pub(crate) async fn restore(
    bus: &BusHandle,
    id: u8,
    previous: u16,
    who: &'static str,
    settled: impl FnOnce() + Send + 'static,
) -> bool {
    if write_back(bus, id, previous, who).await {
        return true;
    }
    owe(bus, id, previous, who, settled);
    false
}

/// Joint `id` of `bus` is owed `previous`: a task of its own writes it back
/// once the joint is online, and again until it reads back.
fn owe(
    bus: &BusHandle,
    id: u8,
    previous: u16,
    who: &'static str,
    settled: impl FnOnce() + Send + 'static,
) {
    if !bus.owed_limits().owe(id, previous) {
        // Already owed (and being retried): the joint's own limit, which
        // the earlier routine found, is the one to give back.
        return;
    }
    tracing::error!(
        bus = bus.name(),
        id,
        previous,
        "{who}: the joint's current limit could not be written back; it is owed, and nothing \
         new moves the joint until it is written and read back"
    );
    let Ok(rt) = tokio::runtime::Handle::try_current() else {
        return;
    };
    let bus = bus.clone();
    rt.spawn(async move {
        let mut snaps = bus.watch();
        loop {
            let online = snaps.borrow().devices.get(&id).is_some_and(|d| d.online);
            if online && write_back(&bus, id, previous, who).await {
                bus.owed_limits().settle(id);
                tracing::info!(
                    bus = bus.name(),
                    id,
                    "{who}: the owed current limit is back"
                );
                settled();
                return;
            }
            // Offline: wait for a snapshot that may say otherwise; online
            // but refused: try again a little later.
            if let Ok(Err(_)) = tokio::time::timeout(OWED_RETRY, snaps.changed()).await {
                return; // the bus is gone: the daemon is stopping
            }
        }
    });
}

/// Writes `previous` back, then reads it back: true only when the
/// read-back shows it. A few tries; a write whose confirmation was lost
/// may still have taken, which the read-back tells. `who` names the
/// routine in the log.
async fn write_back(bus: &BusHandle, id: u8, previous: u16, who: &str) -> bool {
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
