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
    let state = AppState::new(vec![bus.handle.clone()], SoftLimits::default(), None);
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
