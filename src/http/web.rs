//! The dashboard (`web/`), embedded in the binary so the one executable
//! serves it. While developing, `--web-dir web` serves the folder from disk
//! instead, so a page reload picks up edits without a rebuild.

use std::path::Path;

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

use crate::http::paths::{DASHBOARD_INDEX, DASHBOARD_PAGE, DASHBOARD_STYLE};
use crate::http::state::AppState;

/// One file of the dashboard.
type Asset = (&'static str, &'static str, &'static str, &'static str);

const HTML: &str = "text/html; charset=utf-8";
const JS: &str = "text/javascript; charset=utf-8";

/// A script of `web/`, served at `/<file>` (listed in
/// `paths::DASHBOARD_SCRIPTS`, which a test keeps equal to these).
macro_rules! script {
    ($file:literal) => {
        (
            concat!("/", $file),
            $file,
            JS,
            include_str!(concat!("../../web/", $file)),
        )
    };
}

/// (URL path, file name, content type, embedded bytes).
const ASSETS: [Asset; 14] = [
    (
        DASHBOARD_PAGE,
        "index.html",
        HTML,
        include_str!("../../web/index.html"),
    ),
    (
        DASHBOARD_INDEX,
        "index.html",
        HTML,
        include_str!("../../web/index.html"),
    ),
    (
        DASHBOARD_STYLE,
        "style.css",
        "text/css; charset=utf-8",
        include_str!("../../web/style.css"),
    ),
    script!("app.js"),
    script!("api.js"),
    script!("moves.js"),
    script!("homing.js"),
    script!("calibration.js"),
    script!("hands.js"),
    script!("grasp.js"),
    script!("recordings.js"),
    script!("ros2.js"),
    script!("doctor.js"),
    script!("scope.js"),
];

/// One route per file; each handler knows its file, so no request can ask
/// for one that is not there. (They need no token: `paths::is_public`.)
pub(crate) fn router() -> Router<AppState> {
    ASSETS.iter().fold(Router::new(), |r, a| {
        r.route(a.0, get(move |State(state)| asset(state, *a)))
    })
}

async fn asset(state: AppState, (_, file, mime, embedded): Asset) -> Response {
    let body = match state.web_dir() {
        Some(dir) => match read_from(dir, file).await {
            Ok(text) => text,
            Err(e) => {
                tracing::warn!(file, error = %e, "cannot read dashboard file from disk; serving the embedded one");
                embedded.to_owned()
            }
        },
        None => embedded.to_owned(),
    };
    (
        [
            (header::CONTENT_TYPE, mime),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn read_from(dir: &Path, file: &str) -> std::io::Result<String> {
    tokio::fs::read_to_string(dir.join(file)).await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::http::paths::{is_public, DASHBOARD_SCRIPTS};

    #[test]
    fn every_script_listed_is_served_and_public() {
        let served: Vec<&str> = ASSETS.iter().map(|a| a.0).collect();
        for url in DASHBOARD_SCRIPTS {
            assert!(served.contains(&url), "{url} is listed but not served");
        }
        for url in served {
            assert!(is_public(url), "{url} is served but needs a token");
        }
    }
}
