//! Answered requests by method, route and status class, and how long each
//! route took to answer: what `jointd_http_requests_total` and
//! `jointd_http_request_duration_seconds` expose.
//!
//! The route is the router's path template (`/api/v1/buses/{bus}/devices/{id}`),
//! never the request's path: every label set stays one of a bounded few,
//! whatever clients send. A path no route matches counts as `unmatched`,
//! a method outside HTTP's usual ones as `other`.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::{MatchedPath, Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::Response;

use crate::histogram::Histogram;

/// The route label of a request no route matched.
pub(crate) const UNMATCHED: &str = "unmatched";

/// Counts and latencies since start. One std `Mutex`: it is held only to
/// add one observation or to copy the maps for a scrape, never across an
/// `.await`.
#[derive(Default)]
pub(crate) struct RequestStats {
    inner: Mutex<Maps>,
}

/// Both maps are ordered so a scrape lists them in a stable order.
#[derive(Default, Clone)]
pub(crate) struct Maps {
    /// (method, route, status class) → answers.
    pub(crate) answered: BTreeMap<(&'static str, String, &'static str), u64>,
    /// (method, route) → time to the answer's head.
    pub(crate) latency: BTreeMap<(&'static str, String), Histogram>,
}

impl RequestStats {
    fn record(&self, method: &'static str, route: String, status: &'static str, took: Duration) {
        let mut maps = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        *maps
            .answered
            .entry((method, route.clone(), status))
            .or_default() += 1;
        maps.latency
            .entry((method, route))
            .or_default()
            .observe(took);
    }

    /// A copy for a scrape (the lock is released before it is rendered).
    pub(crate) fn snapshot(&self) -> Maps {
        self.inner.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
}

/// Middleware: counts each answer once, when its head is ready (a
/// WebSocket upgrade once, as its 101; a streamed body goes on after).
pub(crate) async fn count(
    State(stats): State<Arc<RequestStats>>,
    req: Request,
    next: Next,
) -> Response {
    let started = Instant::now();
    let method = method_label(req.method());
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| UNMATCHED.to_owned(), |p| p.as_str().to_owned());
    let resp = next.run(req).await;
    let status = status_class(resp.status().as_u16());
    stats.record(method, route, status, started.elapsed());
    resp
}

/// The method as a label: the usual ones by name, any other as `other`
/// (extension methods are client-chosen tokens).
fn method_label(m: &Method) -> &'static str {
    const KNOWN: [(Method, &str); 7] = [
        (Method::GET, "GET"),
        (Method::HEAD, "HEAD"),
        (Method::POST, "POST"),
        (Method::PUT, "PUT"),
        (Method::PATCH, "PATCH"),
        (Method::DELETE, "DELETE"),
        (Method::OPTIONS, "OPTIONS"),
    ];
    KNOWN
        .iter()
        .find(|(k, _)| k == m)
        .map_or("other", |(_, name)| name)
}

/// `2xx` for 200..=299 and so on; `other` outside 100..=599 (HTTP allows
/// up to 999; the daemon sends none of those).
fn status_class(status: u16) -> &'static str {
    match status / 100 {
        1 => "1xx",
        2 => "2xx",
        3 => "3xx",
        4 => "4xx",
        5 => "5xx",
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_stay_in_bounded_sets() {
        assert_eq!(method_label(&Method::PATCH), "PATCH");
        let odd = Method::from_bytes(b"BREW").unwrap();
        assert_eq!(method_label(&odd), "other");
        assert_eq!(status_class(101), "1xx");
        assert_eq!(status_class(204), "2xx");
        assert_eq!(status_class(422), "4xx");
        assert_eq!(status_class(503), "5xx");
        assert_eq!(status_class(799), "other");
    }

    #[test]
    fn records_count_per_status_and_time_per_route() {
        let s = RequestStats::default();
        let route = || "/api/v1/buses/{bus}".to_owned();
        s.record("GET", route(), "2xx", Duration::from_micros(300));
        s.record("GET", route(), "2xx", Duration::from_millis(3));
        s.record("GET", route(), "4xx", Duration::from_millis(1));
        let m = s.snapshot();
        assert_eq!(m.answered[&("GET", route(), "2xx")], 2);
        assert_eq!(m.answered[&("GET", route(), "4xx")], 1);
        assert_eq!(m.latency[&("GET", route())].count(), 3);
    }
}
