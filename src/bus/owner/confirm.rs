//! How a device's answer to a one-shot request reads: a RES code, the
//! words an error uses for a config frame, and the error of a write whose
//! answer was lost.

use crate::bus::error::BusError;
use crate::bus::handle::BusCounters;
use crate::protocol::reply::RES_SUCCESS;
use crate::protocol::{ConfigParam, Reply, ReplyBody};

/// What a config frame does, for error messages.
pub(super) fn describe(param: &ConfigParam) -> String {
    let (index, value) = param.index_value();
    match param {
        ConfigParam::ReadInfo(block) => format!("read {block:?}"),
        _ => format!("write index {index} = {value}"),
    }
}

/// Checks a RES reply: 1 is success.
pub(super) fn check_res(reply: &Reply, param: &ConfigParam) -> Result<(), BusError> {
    match reply.body() {
        ReplyBody::Res { code, .. } if code == RES_SUCCESS => Ok(()),
        ReplyBody::Res { code, .. } => Err(BusError::Refused {
            dev_id: reply.dev_id,
            what: describe(param),
            code,
        }),
        _ => Err(BusError::UnexpectedReply(format!(
            "device {} answered {} with index {} instead of RES",
            reply.dev_id,
            describe(param),
            reply.index
        ))),
    }
}

/// The error of a write that went out and stayed unconfirmed (counted).
pub(super) fn unverified(
    counters: &mut BusCounters,
    dev_id: u8,
    param: &ConfigParam,
    reason: String,
) -> BusError {
    counters.writes_unverified += 1;
    let (index, value) = param.index_value();
    BusError::Unverified {
        dev_id,
        index,
        value,
        what: describe(param),
        reason,
    }
}
