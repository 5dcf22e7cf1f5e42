//! `firmware = "auto"`: asking a device its protocol revision. A rev 2.0.8
//! device answers an `INFO_07` read with its serial number; a V2.0.1 device
//! does not know index 32 and stays silent. Silence is only taken for
//! V2.0.1 when the device still answers an `INFO_01` read right after: a
//! device that went away tells nothing, and is asked again when it is back.

use crate::bus::firmware::{DeviceFirmware, FirmwareSource};
use crate::bus::wire::Want;
use crate::protocol::params::Revision;
use crate::protocol::{Config, InfoBlock, ReplyBody};

use super::ctx::Ctx;
use super::jobs;

pub(super) fn probe(ctx: &mut Ctx, id: u8) {
    ctx.sched_mut().job_start();
    let want = Want {
        dev_id: id,
        index: InfoBlock::Info07.index(),
    };
    // As many tries as any read gets: noise must not make a 2.0.8 device a 2.0.1.
    let attempts = 1 + ctx.cfg().timing.retries;
    let found = match ctx.probe(Config::read(id, InfoBlock::Info07), want, attempts) {
        Ok(Some(reply)) => match reply.body() {
            ReplyBody::Info07(serial) => Some((Revision::V2_0_8, Some(serial))),
            _ => None,
        },
        Ok(None) => match jobs::read_info01(ctx, id) {
            Ok(_) => Some((Revision::V2_0_1, None)),
            Err(e) => {
                tracing::info!(bus = %ctx.name(), dev_id = id,
                    "firmware probe: device {id} answered nothing ({e}); asking again when it is back");
                None
            }
        },
        // An e-stop took the line, or the bus went down: asked again later.
        Err(_) => None,
    };
    let Some((revision, serial)) = found else {
        return;
    };
    tracing::info!(bus = %ctx.name(), dev_id = id, firmware = revision.as_str(),
        "device {id} runs protocol revision {} (detected: {})",
        revision.as_str(),
        if serial.is_some() { "it answered INFO_07" } else { "no answer to INFO_07" });
    ctx.sched_mut().firmware_known(
        id,
        DeviceFirmware {
            revision,
            source: FirmwareSource::Detected,
            serial,
        },
    );
}
