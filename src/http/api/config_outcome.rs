//! What a configuration PATCH did to each parameter: written (confirmed),
//! unverified (sent, confirmation lost) or not written. Its own file so the
//! handlers and the OpenAPI document's shared components can both name
//! these types without importing each other.

use serde::Serialize;
use utoipa::ToSchema;

use super::config_params::Param;
use crate::bus::handle::WriteOutcome;

/// One verified write.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Written {
    #[schema(example = "max_current_a")]
    pub param: &'static str,
    #[schema(example = 2.0)]
    pub value: f64,
    #[schema(example = 11650)]
    pub raw: u16,
    #[schema(example = 18)]
    pub index: u8,
    /// `res` (the device's RES reply) or `read_back` (the INFO block read back).
    #[schema(example = "read_back")]
    pub verified_by: &'static str,
}

/// A parameter sent whose confirmation (read-back or RES) was lost after
/// the retries: the device may or may not have the value.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Unverified {
    #[schema(example = "max_current_a")]
    pub param: &'static str,
    #[schema(example = 2.0)]
    pub value: f64,
    #[schema(example = 11650)]
    pub raw: u16,
    #[schema(example = 18)]
    pub index: u8,
    #[schema(example = "no read-back answered after 3 send(s)")]
    pub reason: String,
}

/// A parameter the device does not have: refused, read back with another
/// value, or never sent (an earlier parameter failed, or the bus could not send).
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct NotWritten {
    #[schema(example = "burst_plus_ms")]
    pub param: &'static str,
    #[schema(example = 100.0)]
    pub value: f64,
    #[schema(example = 4)]
    pub raw: u16,
    #[schema(example = 27)]
    pub index: u8,
    #[schema(example = "not sent: an earlier parameter failed")]
    pub reason: String,
}

/// Every parameter of a PATCH in one of three lists, each in request
/// order: the `partial` member of a PATCH that did not confirm everything.
#[derive(Debug, Default, Serialize, ToSchema)]
pub(crate) struct PatchOutcomes {
    /// Confirmed on the device (RAM only until persisted).
    pub written: Vec<Written>,
    /// Sent, confirmation lost: the device may or may not have them.
    pub unverified: Vec<Unverified>,
    /// Not on the device (refused, read back otherwise, or never sent).
    pub not_written: Vec<NotWritten>,
}

impl Written {
    pub(crate) fn new(param: Param, value: f64, outcome: &WriteOutcome) -> Self {
        Self {
            param: param.key,
            value,
            raw: outcome.value,
            index: outcome.index,
            verified_by: outcome.verified_by,
        }
    }
}

impl Unverified {
    pub(crate) fn new(param: Param, value: f64, raw: u16, reason: String) -> Self {
        Self {
            param: param.key,
            value,
            raw,
            index: param.index,
            reason,
        }
    }
}

/// Why a parameter after a failed one is `not_written`.
pub(crate) const NOT_SENT: &str = "not sent: an earlier parameter failed";

impl NotWritten {
    pub(crate) fn new(param: Param, value: f64, raw: u16, reason: String) -> Self {
        Self {
            param: param.key,
            value,
            raw,
            index: param.index,
            reason,
        }
    }
}
