//! `GET /api/v1/caller`: the token a request came with, by its name and
//! scope (never the token itself), so a client such as the dashboard
//! offers only what it may do.

use axum::{Extension, Json};
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::openapi::{ErrorResponses, TAG_HEALTH};
use crate::http::state::AppState;
use crate::http::tokens::Caller;

pub(crate) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(caller))
}

/// Who a request is, to the daemon.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct CallerView {
    /// The token's name (`token` for `--token`; `open` when the daemon takes no token).
    #[schema(example = "dashboard")]
    pub name: String,
    /// `read`, `operate` or `admin`.
    #[schema(example = "read")]
    pub scope: &'static str,
    /// Whether the daemon takes tokens at all (false: everyone may do all).
    #[schema(example = true)]
    pub auth: bool,
}

/// The token this request came with: its name and scope.
///
/// What the token may do is its scope: `read` looks, `operate` moves, `admin`
/// configures; every token may e-stop. The dashboard greys out what it may not.
#[utoipa::path(get, path = "/api/v1/caller", tag = TAG_HEALTH,
    responses((status = 200, description = "The token's name and scope", body = CallerView), ErrorResponses))]
async fn caller(
    axum::extract::State(state): axum::extract::State<AppState>,
    caller: Option<Extension<Caller>>,
) -> Json<CallerView> {
    let caller = caller.map_or_else(Caller::unknown, |Extension(c)| c);
    Json(CallerView {
        name: caller.name,
        scope: caller.scope.name(),
        auth: !state.tokens().is_empty(),
    })
}
