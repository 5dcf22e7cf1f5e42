//! The doctor's checks of a configured bus: the report `jointd doctor PATH`
//! prints, run on the port the bus's owner lends between its frames.

use axum::extract::State;
use axum::Json;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_BUSES};
use crate::doctor::Report;
use crate::http::error::ApiResult;
use crate::http::extract::ApiPath;
use crate::http::state::{AppState, BusPath};

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(doctor))
}

/// Check the bus's port, adapter, line and devices against what jointd assumes.
///
/// The same report as `jointd doctor PATH --json` (docs/hardware.md): each check with its
/// verdict and what to do, the facts measured, and the bus config the doctor proposes with the
/// rates to expect on it. It sends only reads: nothing is enabled, moved or written. The bus
/// lends its port for the run (a few seconds; up to a minute when the devices answer at no
/// baud): polling pauses meanwhile and resumes after. Refused (409) while a joint of the bus is
/// enabled. An e-stop stops the run at its next frame.
#[utoipa::path(post, path = "/api/v1/buses/{bus}/doctor", tag = TAG_BUSES, params(BusPath),
    responses((status = 200, description = "The doctor's report (`jointd doctor --json`), abridged here",
        body = Object, example = json!({
            "jointd": "0.1.0", "path": "/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K5XYZ-if00-port0",
            "baud_asked": 500000, "verdict": "warn", "held": false,
            "checks": [
                {"id": "open", "verdict": "ok",
                 "found": "lent by bus bus0 at 500000 baud; its polling paused for the run"},
                {"id": "latency_timer", "verdict": "warn", "found": "latency timer 16 ms",
                 "fix": "set it to 1 ms: echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB0/latency_timer"},
                {"id": "devices", "verdict": "ok", "found": "4 devices answer at 500000 baud: 1-4"}
            ],
            "devices": [{"id": 1, "firmware": "1.2.8", "revision": "2.0.8"}],
            "proposal": {"toml": "[[bus]]\nname = \"bus0\"\n…"}
        })), ErrorResponses))]
async fn doctor(
    State(state): State<AppState>,
    ApiPath(p): ApiPath<BusPath>,
) -> ApiResult<Json<Report>> {
    Ok(Json(state.control().doctor(&p.bus).await?))
}
