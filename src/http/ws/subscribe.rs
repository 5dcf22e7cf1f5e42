//! A `subscribe` message checked into a subscription: buses and devices
//! each named once, the rate within its bounds, the fields.

use super::messages::{ErrorCode, Field, Subscribe};
use super::setpoints::WsError;
use super::telemetry::Subscription;
use crate::control::ControlError;
use crate::http::state::device_id;
use crate::http::state::AppState;

/// Telemetry rate bounds and default, messages per second.
pub(crate) const MAX_RATE_HZ: f64 = 1000.0;
pub(super) const MIN_RATE_HZ: f64 = 1.0;
pub(super) const DEFAULT_RATE_HZ: f64 = 50.0;

pub(super) fn subscription(state: &AppState, s: &Subscribe) -> Result<Subscription, WsError> {
    let buses = match &s.buses {
        Some(names) => {
            for (i, n) in names.iter().enumerate() {
                state.control().reader(n)?;
                if names[..i].contains(n) {
                    return Err(ControlError::duplicate(
                        &format!("buses[{i}]"),
                        format!("bus `{n}` appears twice"),
                    )
                    .into());
                }
            }
            names.clone()
        }
        None => state
            .control()
            .readers()
            .map(|b| b.name().to_owned())
            .collect(),
    };
    let devices = match &s.devices {
        Some(ids) => {
            let ids = ids
                .iter()
                .map(|&id| device_id("devices", id))
                .collect::<Result<Vec<u8>, _>>()?;
            if let Some(i) = (1..ids.len()).find(|&i| ids[..i].contains(&ids[i])) {
                return Err(ControlError::duplicate(
                    &format!("devices[{i}]"),
                    format!("device {} appears twice", ids[i]),
                )
                .into());
            }
            Some(ids)
        }
        None => None,
    };
    let rate_hz = s.rate_hz.unwrap_or(DEFAULT_RATE_HZ);
    if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz) {
        let mut e = WsError::new(
            ErrorCode::OutOfRange,
            format!("rate_hz = {rate_hz} is out of range; allowed {MIN_RATE_HZ}..={MAX_RATE_HZ}"),
        );
        e.field = Some("rate_hz".into());
        return Err(e);
    }
    let fields = s.fields.clone().unwrap_or_else(|| Field::ALL.to_vec());
    Ok(Subscription::new(buses, devices, fields, rate_hz))
}
