//! How a device's answer to a one-shot request reads: a RES code, and the
//! words an error uses for a config frame.

use crate::bus::error::BusError;
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
