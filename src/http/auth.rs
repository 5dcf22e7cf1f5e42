//! Bearer-token auth. When tokens are configured, every request but the
//! public paths (`/healthz`, the dashboard files) must carry
//! `Authorization: Bearer <token>`: a missing or unknown token is a 401
//! problem, a token whose scope does not reach the route a 403 naming the
//! scope it needed. With no token the API is open (the daemon refuses to
//! listen beyond loopback that way unless told `--insecure`).

use axum::extract::{MatchedPath, Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::paths::{is_public, WS_PATH};
use super::scope::{needs, Needs, Scope};
use super::state::AppState;
use super::tokens::Caller;
use crate::control::audit::Command;

const BEARER: &str = "Bearer ";

/// Finds the request's token, checks that its scope reaches what the
/// route needs ([`super::scope::needs`]: 403 saying which scope it
/// needed), and passes the request on with its [`Caller`]. With no token
/// configured, everyone is an (open) admin.
pub(crate) async fn require_token(
    State(state): State<AppState>,
    mut req: Request,
    next: Next,
) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|m| m.as_str().to_owned());
    let needs = needs(req.method(), route.as_deref());
    let tokens = state.tokens();
    let caller = if tokens.is_empty() {
        Caller::open()
    } else if is_public(req.uri().path()) {
        return next.run(req).await;
    } else {
        let presented = req
            .headers()
            .get(AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(bearer_token)
            .map(str::to_owned)
            .or_else(|| websocket_query_token(&req));
        let Some(presented) = presented else {
            return ApiError::unauthorized("send `Authorization: Bearer <token>`").into_response();
        };
        let Some(token) = tokens.find(&presented) else {
            return ApiError::unauthorized("the bearer token is not valid").into_response();
        };
        if !needs.allows(token.scope) {
            return ApiError::insufficient_scope(needs, &token.name, token.scope).into_response();
        }
        Caller::from(token)
    };
    // Motion, configuration and the e-stop are told with who sent them.
    let told = (needs != Needs::Scope(Scope::Read))
        .then(|| (req.method().to_string(), req.uri().path().to_owned()));
    req.extensions_mut().insert(caller.clone());
    let resp = next.run(req).await;
    if let Some((method, path)) = told {
        let kind = format!("{method} {}", route.as_deref().unwrap_or(&path));
        let what = format!("{method} {path}");
        let status = resp.status();
        let cmd = Command {
            by: &caller.name,
            kind: &kind,
            what: &what,
            outcome: status.as_str(),
        };
        let bus = route.as_deref().and_then(|r| bus_of(r, &path));
        state.control().tell(&cmd, bus);
    }
    resp
}

/// The `{bus}` of a path, found where the route's template has it.
fn bus_of<'a>(route: &str, path: &'a str) -> Option<&'a str> {
    let at = route.split('/').position(|s| s == "{bus}")?;
    path.split('/').nth(at)
}

/// Browsers cannot set headers on a WebSocket upgrade, so the WebSocket
/// endpoint (only) also takes `?token=`, percent-encoded (the dashboard
/// sends `encodeURIComponent(token)`). A malformed encoding is a wrong token.
fn websocket_query_token(req: &Request) -> Option<String> {
    if req.uri().path() != WS_PATH {
        return None;
    }
    let raw = req
        .uri()
        .query()?
        .split('&')
        .find_map(|pair| pair.strip_prefix("token="))?;
    Some(percent_decode(raw).unwrap_or_default())
}

/// RFC 3986 percent-decoding; `+` stays a plus (it is not form encoding:
/// `encodeURIComponent` writes a space as `%20` and a plus as `%2B`).
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = text.get(i + 1..i + 3)?;
            if !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
                return None;
            }
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The token of an `Authorization` value; the scheme is case-insensitive.
fn bearer_token(value: &str) -> Option<&str> {
    let scheme = value.get(..BEARER.len())?;
    scheme
        .eq_ignore_ascii_case(BEARER)
        .then(|| value[BEARER.len()..].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bus_of_a_path_is_where_its_route_says() {
        let route = "/api/v1/buses/{bus}/devices/{id}/target";
        assert_eq!(
            bus_of(route, "/api/v1/buses/left/devices/3/target"),
            Some("left")
        );
        assert_eq!(bus_of("/api/v1/moves", "/api/v1/moves"), None);
    }

    #[test]
    fn bearer_scheme_is_case_insensitive_and_exact() {
        assert_eq!(bearer_token("Bearer abc"), Some("abc"));
        assert_eq!(bearer_token("bearer abc"), Some("abc"));
        assert_eq!(bearer_token("Basic abc"), None);
        assert_eq!(bearer_token("Bear"), None);
    }

    #[test]
    fn query_tokens_are_percent_decoded() {
        assert_eq!(
            percent_decode("a%2Fb%2B%3D%20c").as_deref(),
            Some("a/b+= c")
        );
        assert_eq!(percent_decode("a+b").as_deref(), Some("a+b"));
        assert_eq!(percent_decode("%E2%9C%93").as_deref(), Some("\u{2713}"));
        assert_eq!(percent_decode("%2"), None);
        assert_eq!(percent_decode("%zz"), None);
        assert_eq!(percent_decode("%+1"), None);
        assert_eq!(percent_decode("%FF"), None);
    }
}
