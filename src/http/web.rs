//! The dashboard (`web/`), embedded in the binary so the one executable
//! serves it. While developing, `--web-dir web` serves the folder from disk
//! instead, so a page reload picks up edits without a rebuild.

use std::path::Path;

use axum::extract::State;
use axum::http::{header, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

use crate::http::AppState;

/// (URL path, file name, content type, embedded bytes).
const ASSETS: [(&str, &str, &str, &str); 4] = [
    (
        "/",
        "index.html",
        "text/html; charset=utf-8",
        include_str!("../../web/index.html"),
    ),
    (
        "/index.html",
        "index.html",
        "text/html; charset=utf-8",
        include_str!("../../web/index.html"),
    ),
    (
        "/app.js",
        "app.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/app.js"),
    ),
    (
        "/style.css",
        "style.css",
        "text/css; charset=utf-8",
        include_str!("../../web/style.css"),
    ),
];

/// The dashboard's files need no token: they hold no data, and the page
/// itself asks for the token when the API answers 401.
pub fn is_public(path: &str) -> bool {
    ASSETS.iter().any(|(p, ..)| *p == path)
}

pub fn router() -> Router<AppState> {
    ASSETS
        .iter()
        .fold(Router::new(), |r, (path, ..)| r.route(path, get(asset)))
}

async fn asset(State(state): State<AppState>, uri: Uri) -> Response {
    let Some((_, file, mime, embedded)) = ASSETS.iter().find(|(p, ..)| *p == uri.path()) else {
        return StatusCode::NOT_FOUND.into_response();
    };
    let body = match state.web_dir() {
        Some(dir) => match read_from(dir, file).await {
            Ok(text) => text,
            Err(e) => {
                tracing::warn!(file, error = %e, "cannot read dashboard file from disk; serving the embedded one");
                (*embedded).to_owned()
            }
        },
        None => (*embedded).to_owned(),
    };
    (
        [
            (header::CONTENT_TYPE, *mime),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn read_from(dir: &Path, file: &str) -> std::io::Result<String> {
    tokio::fs::read_to_string(dir.join(file)).await
}
