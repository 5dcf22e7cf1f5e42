//! Every URL the HTTP layer serves outside the OpenAPI routes, and which of
//! them need no token. Kept apart so auth, the WebSocket and the dashboard
//! agree on them without importing each other.

/// The WebSocket endpoint.
pub(crate) const WS_PATH: &str = "/api/v1/ws";
/// Liveness: public even when the daemon has a token.
pub(crate) const HEALTHZ_PATH: &str = "/healthz";
/// The OpenAPI document and its docs page.
pub(crate) const OPENAPI_PATH: &str = "/openapi.json";
pub(crate) const DOCS_PATH: &str = "/docs";
/// The dashboard's files (`web/`): the page, its style and its scripts
/// (ES modules, one job each; `app.js` is the one the page loads).
pub(crate) const DASHBOARD_PAGE: &str = "/";
pub(crate) const DASHBOARD_INDEX: &str = "/index.html";
pub(crate) const DASHBOARD_STYLE: &str = "/style.css";
pub(crate) const DASHBOARD_SCRIPTS: [&str; 11] = [
    "/app.js",
    "/api.js",
    "/moves.js",
    "/homing.js",
    "/calibration.js",
    "/hands.js",
    "/grasp.js",
    "/recordings.js",
    "/ros2.js",
    "/scope.js",
    "/doctor.js",
];
const DASHBOARD: [&str; 3] = [DASHBOARD_PAGE, DASHBOARD_INDEX, DASHBOARD_STYLE];

/// Paths that need no token: `/healthz` (probes carry none) and the
/// dashboard's files (they hold no data; the page asks for the token when
/// the API answers 401).
pub(crate) fn is_public(path: &str) -> bool {
    path == HEALTHZ_PATH || DASHBOARD.contains(&path) || DASHBOARD_SCRIPTS.contains(&path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_probes_and_dashboard_files_are_public() {
        assert!(is_public("/healthz"));
        assert!(is_public("/") && is_public("/app.js") && is_public("/moves.js"));
        assert!(!is_public("/readyz"));
        assert!(!is_public(WS_PATH));
        assert!(!is_public("/api/v1/buses"));
    }
}
