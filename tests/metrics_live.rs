//! Families a live daemon fills by running: the `process_*` ones (read from
//! `/proc/self`, plausible for this very process) and the HTTP requests
//! counted by route template and status class.

mod support;

use std::time::{SystemTime, UNIX_EPOCH};

use jointd::control::limits::SoftLimits;
use jointd::http::AppState;
use support::fake_bus::FakeBus;
use support::http::{serve, Server};

async fn setup() -> (FakeBus, Server) {
    let bus = FakeBus::new("fake", &[1, 2]);
    let state = AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            SoftLimits::default(),
        )),
        None,
    );
    (bus, serve(state).await)
}

async fn scrape(s: &Server) -> String {
    let r = s.get("/metrics").await;
    assert!(r.status.is_success(), "{}", r.status);
    r.body.as_str().expect("text").to_owned()
}

/// The value of the sample whose name and labels are exactly `series`.
fn sample(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .map(|v| v.parse().expect("a number"))
}

fn must(text: &str, series: &str) -> f64 {
    sample(text, series).unwrap_or_else(|| panic!("no sample {series} in:\n{text}"))
}

#[tokio::test]
async fn process_families_are_plausible_for_this_process() {
    let (_bus, s) = setup().await;
    let text = scrape(&s).await;
    let rss = must(&text, "process_resident_memory_bytes");
    let vsz = must(&text, "process_virtual_memory_bytes");
    assert!(rss > 0.0 && vsz >= rss, "rss {rss}, virtual {vsz}");
    // stdin, stdout, stderr, and the test's own sockets at least.
    let open = must(&text, "process_open_fds");
    let max = must(&text, "process_max_fds");
    assert!(open >= 3.0 && max >= open, "open {open}, max {max}");
    let cpu = must(&text, "process_cpu_seconds_total");
    assert!(cpu >= 0.0, "{cpu}");
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_secs_f64();
    let start = must(&text, "process_start_time_seconds");
    // Boot time is whole seconds, rounded down: a start can read early,
    // never late; the slack is for the clock being stepped meanwhile.
    assert!(start <= now + 1.0, "start {start} after now {now}");
    assert!(now - start < 3600.0, "start {start}, now {now}");
    // Counters and gauges of one process: each family once.
    for name in ["process_cpu_seconds_total", "process_open_fds"] {
        let types = text
            .lines()
            .filter(|l| l.starts_with(&format!("# TYPE {name} ")))
            .count();
        assert_eq!(types, 1, "{name}");
    }
}

const DEVICE: &str = "/api/v1/buses/{bus}/devices/{id}";
const TARGET: &str = "/api/v1/buses/{bus}/devices/{id}/target";

fn requests(method: &str, route: &str, status: &str) -> String {
    format!(
        "jointd_http_requests_total{{method=\"{method}\",route=\"{route}\",status=\"{status}\"}}"
    )
}

#[tokio::test]
async fn requests_count_by_route_template_and_status_class() {
    let (_bus, s) = setup().await;
    let dev = "/api/v1/buses/fake/devices";
    s.get(&format!("{dev}/1")).await.ok();
    s.get(&format!("{dev}/9")).await.problem(404);
    s.get(&format!("{dev}/2")).await.ok();
    // Not JSON (400), then JSON of the wrong shape (422).
    let not_json = s
        .client
        .put(format!("{}{dev}/1/target", s.base))
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .expect("request");
    assert_eq!(not_json.status(), 400);
    s.put(
        &format!("{dev}/1/target"),
        serde_json::json!({"position_deg": "ten"}),
    )
    .await
    .problem(422);
    s.get("/api/v1/nothing-here/42").await.problem(404);
    s.call(reqwest::Method::DELETE, "/api/v1/buses", None)
        .await
        .problem(405);
    let ws_url = format!("{}/api/v1/ws", s.base.replace("http://", "ws://"));
    let (ws, resp) = tokio_tungstenite::connect_async(ws_url)
        .await
        .expect("upgrade");
    assert_eq!(resp.status().as_u16(), 101);
    drop(ws);

    let text = scrape(&s).await;
    assert_eq!(must(&text, &requests("GET", DEVICE, "2xx")), 2.0);
    assert_eq!(must(&text, &requests("GET", DEVICE, "4xx")), 1.0);
    assert_eq!(must(&text, &requests("PUT", TARGET, "4xx")), 2.0);
    assert_eq!(must(&text, &requests("GET", "unmatched", "4xx")), 1.0);
    assert_eq!(
        must(&text, &requests("DELETE", "/api/v1/buses", "4xx")),
        1.0
    );
    assert_eq!(must(&text, &requests("GET", "/api/v1/ws", "1xx")), 1.0);
    assert_eq!(sample(&text, &requests("PUT", TARGET, "2xx")), None);
    // The first scrape is counted once answered: the second sees it.
    let text = scrape(&s).await;
    assert_eq!(must(&text, &requests("GET", "/metrics", "2xx")), 1.0);
    // Never a raw path: no label holds a request's own id or path.
    for raw in ["/devices/9", "/devices/1\"", "nothing-here"] {
        assert!(!text.contains(raw), "{raw} in:\n{text}");
    }
    let latency = "jointd_http_request_duration_seconds";
    let count = format!("{latency}_count{{method=\"GET\",route=\"{DEVICE}\"}}");
    assert_eq!(must(&text, &count), 3.0);
    let inf = format!("{latency}_bucket{{method=\"PUT\",route=\"{TARGET}\",le=\"+Inf\"}}");
    assert_eq!(must(&text, &inf), 2.0);
}
