//! `jointd_http_requests_total` and `jointd_http_request_duration_seconds`
//! from the HTTP layer's [`RequestStats`](crate::http::request_stats).
//! Both families are listed from the first scrape, with no sample until a
//! request has been answered (a scrape counts once its answer is ready, so
//! it shows in the next one).

use super::exposition::{label, Exposition};
use crate::http::state::AppState;

const REQUESTS: &str = "jointd_http_requests_total";
const REQUESTS_HELP: &str =
    "HTTP requests answered, by method, route template (unmatched: no route) and status class.";
const DURATION: &str = "jointd_http_request_duration_seconds";
const DURATION_HELP: &str =
    "A request's arrival to its answer's head being ready, by method and route template.";

pub(super) fn families(m: &mut Exposition, state: &AppState) {
    let maps = state.requests().snapshot();
    m.family(REQUESTS, "counter", REQUESTS_HELP);
    for ((method, route, status), n) in &maps.answered {
        let l = format!(
            "method=\"{method}\",route=\"{}\",status=\"{status}\"",
            label(route)
        );
        m.counter(REQUESTS, REQUESTS_HELP, &l, *n as f64);
    }
    m.family(DURATION, "histogram", DURATION_HELP);
    for ((method, route), h) in &maps.latency {
        let l = format!("method=\"{method}\",route=\"{}\"", label(route));
        m.histogram(DURATION, DURATION_HELP, &l, h);
    }
}
