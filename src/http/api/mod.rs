//! The REST areas, one router each. This module merges them into the one
//! documented router; the areas never import each other's routers (they
//! share only the OpenAPI tags and failure responses of [`openapi`]).
//!
//! # Layout
//! - [`buses`], [`devices`], [`control`], [`config`] and [`config_all`] (a
//!   whole bus at once) (with [`config_params`]:
//!   request values → writes; [`config_schema`]: the schemas from the parameter
//!   table; [`config_outcome`]: what a PATCH did per parameter),
//!   [`estop`], [`health`], [`moves`] (paths generated in the daemon),
//!   [`hands`] (named hands), [`poses`] (their poses), [`calibration`] (joint
//!   offsets, directions, ranges), [`homing`] (finding hard stops),
//!   [`grasp`] (closing a hand on an object), [`doctor`] (a bus's port checked),
//!   [`recordings`] (MCAP files), [`ros2`] (the bridge's counters): one
//!   router per area.
//! - [`openapi`]: the document's head, the shared failure responses, the docs page.

pub(crate) mod buses;
pub(crate) mod calibration;
pub(crate) mod caller;
pub(crate) mod config;
pub(crate) mod config_all;
pub(crate) mod config_outcome;
pub(crate) mod config_params;
pub(crate) mod config_schema;
pub(crate) mod control;
pub(crate) mod devices;
pub(crate) mod doctor;
pub(crate) mod estop;
pub(crate) mod grasp;
pub(crate) mod hands;
pub(crate) mod health;
pub(crate) mod homing;
pub(crate) mod metrics;
pub(crate) mod moves;
pub(crate) mod openapi;
pub(crate) mod poses;
pub(crate) mod recordings;
pub(crate) mod ros2;

use utoipa_axum::router::OpenApiRouter;

use crate::http::state::AppState;

/// Every documented route, with its part of the document.
pub fn router() -> OpenApiRouter<AppState> {
    openapi::base()
        .merge(health::router())
        .merge(caller::router())
        .merge(buses::router())
        .merge(doctor::router())
        .merge(devices::router())
        .merge(control::router())
        .merge(config::router())
        .merge(config_all::router())
        .merge(estop::router())
        .merge(moves::router())
        .merge(hands::router())
        .merge(poses::router())
        .merge(calibration::router())
        .merge(homing::router())
        .merge(grasp::router())
        .merge(recordings::router())
        .merge(ros2::router())
}

/// The document as served, with the crate version.
pub fn document() -> utoipa::openapi::OpenApi {
    let (_, mut doc) = router().split_for_parts();
    openapi::finish(&mut doc);
    doc
}

/// The document as pretty JSON, as checked in under `openapi/` and printed
/// by `jointd openapi`.
pub fn document_json() -> String {
    openapi::to_json(&document())
}
