//! `firmware = "auto"`: asking a device its protocol revision. A rev 2.0.8
//! device answers an `INFO_07` read with its serial number; a V2.0.1 device
//! does not know index 32 and stays silent. One read per slot, between the
//! bus's usual work: the scheduler counts the silences and takes enough of
//! them in a row, from a device that keeps answering its polls, for V2.0.1.

use crate::bus::firmware::{DeviceFirmware, FirmwareSource};
use crate::bus::wire::Want;
use crate::protocol::params::Revision;
use crate::protocol::{Config, InfoBlock, ReplyBody};

use super::ctx::Ctx;

pub(super) fn probe(ctx: &mut Ctx, id: u8) {
    ctx.sched_mut().job_start();
    let want = Want {
        dev_id: id,
        index: InfoBlock::Info07.index(),
    };
    let found = match ctx.probe(Config::read(id, InfoBlock::Info07), want) {
        Ok(Some(reply)) => match reply.body() {
            ReplyBody::Info07(serial) => {
                let firmware = DeviceFirmware {
                    revision: Revision::V2_0_8,
                    source: FirmwareSource::Detected,
                    serial: Some(serial),
                };
                ctx.sched_mut().firmware_known(id, firmware);
                Some(("it answered INFO_07", Revision::V2_0_8))
            }
            _ => None,
        },
        Ok(None) => ctx
            .sched_mut()
            .probe_unanswered(id)
            .map(|r| ("INFO_07 unanswered, polls answered", r)),
        // An e-stop took the line, or the bus went down: asked again later.
        Err(_) => None,
    };
    if let Some((how, revision)) = found {
        tracing::info!(bus = %ctx.name(), dev_id = id, firmware = revision.as_str(),
            "device {id} runs protocol revision {} (detected: {how})", revision.as_str());
    }
}
