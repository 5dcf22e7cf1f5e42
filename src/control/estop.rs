//! The e-stop's fan-out, for every front-end: every bus named is stopped
//! concurrently (each disables its devices ahead of anything queued and
//! reads them back), and what each did is reported. The motion epochs of
//! every joint advance at the call (`BusHandle::estop`), before any owner
//! writes a frame.

use std::time::Instant;

use serde::Serialize;
use utoipa::ToSchema;

use crate::bus::BusHandle;

/// What the e-stop did on one bus.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct BusStop {
    #[schema(example = "sim0")]
    pub bus: String,
    /// True when every disable frame was written and no device read back
    /// still driving its motor.
    #[schema(example = true)]
    pub stopped: bool,
    /// Disable frames written (`0xFF` first, then one per known device).
    #[schema(example = 17)]
    pub frames_sent: u32,
    /// Queued requests failed because the e-stop went first.
    #[schema(example = 2)]
    pub preempted_requests: u32,
    /// From the call to the first disable frame handed to the port, µs.
    #[schema(example = 180)]
    pub latency_us: u64,
    /// Devices read back afterwards not driving their motor.
    #[schema(example = json!([1, 2, 3]))]
    pub confirmed: Vec<u8>,
    /// Devices read back still driving, which were sent their own disable
    /// again (each is then in `confirmed` or `still_enabled`).
    #[schema(example = json!([]))]
    pub disabled_again: Vec<u8>,
    /// Devices still driving after that second disable: NOT stopped.
    #[schema(example = json!([]))]
    pub still_enabled: Vec<u8>,
    /// Devices whose state could not be read back (offline or silent):
    /// they were sent the disables, but nothing confirms they stopped.
    #[schema(example = json!([]))]
    pub unconfirmed: Vec<u8>,
    /// Why this bus could not be stopped, if it could not.
    pub error: Option<String>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct EstopResult {
    #[schema(example = true)]
    pub stopped: bool,
    pub buses: Vec<BusStop>,
    /// Wall time of the whole call, µs.
    #[schema(example = 950)]
    pub elapsed_us: u64,
}

async fn stop_one(bus: BusHandle) -> BusStop {
    match bus.estop().await {
        Ok(r) => BusStop {
            bus: r.bus,
            stopped: r.still_enabled.is_empty(),
            frames_sent: r.frames_sent,
            preempted_requests: r.preempted_requests,
            latency_us: r.latency_us,
            error: (!r.still_enabled.is_empty()).then(|| {
                format!(
                    "device(s) {:?} still enabled after a second disable",
                    r.still_enabled
                )
            }),
            confirmed: r.confirmed,
            disabled_again: r.disabled_again,
            still_enabled: r.still_enabled,
            unconfirmed: r.unconfirmed,
        },
        Err(e) => BusStop {
            bus: bus.name().to_owned(),
            stopped: false,
            frames_sent: 0,
            preempted_requests: 0,
            latency_us: 0,
            error: Some(e.to_string()),
            confirmed: Vec::new(),
            disabled_again: Vec::new(),
            still_enabled: Vec::new(),
            unconfirmed: Vec::new(),
        },
    }
}

/// Stops `buses` concurrently, polled in the caller's task (a spawned task
/// would wait for a worker behind whatever else is queued).
pub async fn stop(buses: Vec<BusHandle>) -> EstopResult {
    let started = Instant::now();
    let mut results = futures_util::future::join_all(buses.into_iter().map(stop_one)).await;
    results.sort_by(|a, b| a.bus.cmp(&b.bus));
    EstopResult {
        stopped: results.iter().all(|r| r.stopped),
        elapsed_us: u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX),
        buses: results,
    }
}
