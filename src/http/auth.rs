//! Bearer-token auth. When a token is configured, every request but
//! the public paths (`/healthz`, the dashboard files) must carry `Authorization: Bearer <token>`; a missing or wrong
//! token is a 401 problem. With no token the API is open (the daemon refuses
//! to listen beyond loopback that way unless told `--insecure`).

use axum::extract::{Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::paths::{is_public, WS_PATH};
use super::state::AppState;

const BEARER: &str = "Bearer ";

pub(crate) async fn require_token(
    State(state): State<AppState>,
    req: Request,
    next: Next,
) -> Response {
    let Some(token) = state.token() else {
        return next.run(req).await;
    };
    if is_public(req.uri().path()) {
        return next.run(req).await;
    }
    let presented = req
        .headers()
        .get(AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer_token)
        .map(str::to_owned)
        .or_else(|| websocket_query_token(&req));
    match presented {
        Some(p) if constant_time_eq(p.as_bytes(), token.as_bytes()) => next.run(req).await,
        Some(_) => ApiError::unauthorized("the bearer token is not valid").into_response(),
        None => ApiError::unauthorized("send `Authorization: Bearer <token>`").into_response(),
    }
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

/// Compares without an early exit, so response time does not reveal how
/// much of a guessed token was right: every byte of the longer input is
/// visited and folded into one accumulator, whatever differs. (The time
/// depends on the lengths only; the presented one is the caller's own.)
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let len_diff = a.len() ^ b.len();
    let longest = a.len().max(b.len());
    let mut diff = 0u8;
    for i in 0..longest {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0xFF);
    }
    diff == 0 && len_diff == 0
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn token_comparison() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
    }
}
