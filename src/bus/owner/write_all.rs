//! One parameter to every device of the bus (`PATCH /buses/{bus}/config`).
//!
//! Rev 2.0.8 firmware takes a config write addressed to id 0xFF (SPEC
//! §4.3): one frame for the whole bus, then each device is read back and
//! answers for itself. A device whose read-back shows another value (or
//! none) gets the write of its own, verified like any write. On a bus where
//! any device runs V2.0.1 or is not known yet, every device gets its own
//! write. A write whose device answers RES is never sent to 0xFF: every
//! device would answer at once and the replies collide.
//!
//! Every device on the line hears a frame to 0xFF, asked or not: one the
//! caller left out (a device the daemon does not manage) and one offline
//! (its replies lost, its receiver maybe not) would take the value
//! unasked, unverified and unreported. So 0xFF carries the write only when
//! every device the bus knows is online and asked; else one write each.

use crate::bus::error::BusError;
use crate::bus::handle::{WriteAllOutcome, WriteOutcome};
use crate::bus::verify::{confirmation, Confirm};
use crate::protocol::params::Revision;
use crate::protocol::{Command, Config, ConfigParam, ALL_DEVICES};

use super::ctx::Ctx;
use super::write::{read_field, write_config, Seen};

pub(super) fn write_all(
    ctx: &mut Ctx,
    ids: Vec<u8>,
    param: ConfigParam,
) -> Result<WriteAllOutcome, BusError> {
    let how = confirmation(&param).map_err(|why| BusError::Invalid(why.to_string()))?;
    let registry = ctx.sched().registry();
    let all_2_0_8 = !ids.is_empty()
        && ids.iter().all(|id| {
            registry
                .get(*id)
                .and_then(|e| e.state.firmware)
                .is_some_and(|f| f.revision >= Revision::V2_0_8)
        });
    let none_unasked = registry
        .ids()
        .iter()
        .all(|id| ids.contains(id) && registry.is_online(*id));
    let silent = !matches!(how, Confirm::Res);
    if !(all_2_0_8 && silent && none_unasked) {
        let per_device = ids
            .into_iter()
            .map(|id| (id, write_config(ctx, id, param)))
            .collect();
        return Ok(WriteAllOutcome {
            one_frame: false,
            per_device,
        });
    }
    ctx.job_send(&[Command::Config(Config {
        dev_id: ALL_DEVICES,
        param,
    })])?;
    let (index, value) = param.index_value();
    let reads = 1 + ctx.cfg().timing.retries;
    let mut per_device = Vec::with_capacity(ids.len());
    for id in ids {
        let result = match how {
            Confirm::ReadBack { block, field } => {
                match read_field(ctx, id, &param, (block, field), reads) {
                    Ok(Seen::Confirmed) => Ok(WriteOutcome {
                        dev_id: id,
                        index,
                        value,
                        verified_by: "read_back",
                    }),
                    // Not seen on this device: it gets its own write.
                    Ok(_) => {
                        ctx.counters().verify_retries += 1;
                        write_config(ctx, id, param)
                    }
                    Err(e) => Err(e),
                }
            }
            _ => Ok(WriteOutcome {
                dev_id: id,
                index,
                value,
                verified_by: "unverifiable",
            }),
        };
        per_device.push((id, result));
    }
    Ok(WriteAllOutcome {
        one_frame: true,
        per_device,
    })
}
