//! `/metrics` and `docs/metrics.md` list the same families: every family a
//! live daemon exposes is documented, and every documented family is
//! exposed (none stale), each with its HELP and TYPE.

mod support;

use std::collections::BTreeSet;

use support::sim_bus::start;

/// Family names of the table in docs/metrics.md (first column, in backticks).
fn documented() -> BTreeSet<String> {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/metrics.md"))
        .expect("docs/metrics.md");
    text.lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split_once('`').map(|(name, _)| name.to_owned()))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_exposed_family_is_documented_and_none_stale() {
    let b = start(2, None).await;
    // Per-device families appear once the devices have answered both polls.
    b.wait_snapshot("telemetry of both devices", |s| {
        s.devices
            .values()
            .filter(|d| d.info01.is_some() && d.info02.is_some())
            .count()
            == 2
    })
    .await;
    let text = b
        .server
        .get("/metrics")
        .await
        .body
        .as_str()
        .expect("text")
        .to_owned();
    let mut exposed = BTreeSet::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("# TYPE ") {
            let name = rest.split(' ').next().expect("a name");
            assert!(
                text.contains(&format!("# HELP {name} ")),
                "{name} has no HELP"
            );
            exposed.insert(name.to_owned());
        }
    }
    let documented = documented();
    let undocumented: Vec<_> = exposed.difference(&documented).collect();
    assert!(
        undocumented.is_empty(),
        "not in docs/metrics.md: {undocumented:?}"
    );
    // Only with a WebSocket client connected.
    let per_client = "jointd_ws_client_dropped_samples_total".to_owned();
    let stale: Vec<_> = documented
        .difference(&exposed)
        .filter(|n| **n != per_client)
        .collect();
    assert!(stale.is_empty(), "documented but not exposed: {stale:?}");
    // No abbreviated units: promtool's lint asks for base units spelt out.
    for name in &exposed {
        for bad in ["_per_s", "_us", "_ms", "window_s", "_hz"] {
            assert!(
                !name.ends_with(bad) && !name.contains(&format!("{bad}_")),
                "{name}"
            );
        }
    }
}
