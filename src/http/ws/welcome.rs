//! The first message a client gets: the protocol it speaks, its client
//! id, the buses with their joints, and the limits of what it may ask.

use super::messages::{self, BusInfo, Limits, ServerMessage};
use super::setpoints::MAX_BATCH;
use super::subscribe::MAX_RATE_HZ;
use crate::http::state::AppState;

pub(super) fn welcome(state: &AppState, client: u64, name: Option<String>) -> ServerMessage {
    let buses = state
        .control()
        .readers()
        .map(|b| {
            let snap = b.snapshot();
            BusInfo {
                name: snap.name.clone(),
                baud: snap.baud,
                devices: snap.devices.keys().copied().collect(),
            }
        })
        .collect();
    ServerMessage::Welcome {
        protocol: messages::PROTOCOL,
        client,
        name,
        buses,
        limits: Limits {
            max_rate_hz: MAX_RATE_HZ,
            max_batch: MAX_BATCH,
        },
    }
}
