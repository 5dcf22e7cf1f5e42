//! CPU time of this process's threads by name, from
//! `/proc/self/task/*/{comm,schedstat}` (nanosecond run time per thread),
//! so the bench can charge the daemon's own threads and nothing else.

use std::collections::BTreeMap;
use std::fs;
use std::time::Duration;

/// Run time of every thread whose name starts with one of `prefixes`,
/// summed per prefix.
pub fn by_prefix(prefixes: &[&str]) -> BTreeMap<String, Duration> {
    let mut out: BTreeMap<String, Duration> = prefixes
        .iter()
        .map(|p| (p.to_string(), Duration::ZERO))
        .collect();
    let Ok(tasks) = fs::read_dir("/proc/self/task") else {
        return out;
    };
    for task in tasks.flatten() {
        let dir = task.path();
        let Ok(comm) = fs::read_to_string(dir.join("comm")) else {
            continue;
        };
        let Some(prefix) = prefixes.iter().find(|p| comm.trim_end().starts_with(**p)) else {
            continue;
        };
        if let Some(t) = run_time(&dir.join("schedstat")) {
            *out.entry(prefix.to_string()).or_default() += t;
        }
    }
    out
}

/// Run time per prefix, in the order of `prefixes` (zero for none running).
pub fn snapshot(prefixes: &[&str]) -> Vec<Duration> {
    let by = by_prefix(prefixes);
    prefixes
        .iter()
        .map(|p| by.get(*p).copied().unwrap_or_default())
        .collect()
}

/// Thread ids of this process whose name starts with `prefix`.
pub fn tids(prefix: &str) -> Vec<libc::pid_t> {
    let Ok(tasks) = fs::read_dir("/proc/self/task") else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter(|t| {
            fs::read_to_string(t.path().join("comm"))
                .is_ok_and(|c| c.trim_end().starts_with(prefix))
        })
        .filter_map(|t| t.file_name().to_str()?.parse().ok())
        .collect()
}

/// First field of a schedstat file: time spent on the CPU, ns.
fn run_time(path: &std::path::Path) -> Option<Duration> {
    let text = fs::read_to_string(path).ok()?;
    let ns: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(Duration::from_nanos(ns))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_busy_named_thread_shows_cpu_time() {
        let t = std::thread::Builder::new()
            .name("cpu-probe-x".into())
            .spawn(|| {
                let before = by_prefix(&["cpu-probe-"]);
                let mut x = 0u64;
                for i in 0..5_000_000u64 {
                    x = x.wrapping_mul(31).wrapping_add(i);
                }
                std::hint::black_box(x);
                let after = by_prefix(&["cpu-probe-"]);
                after["cpu-probe-"] > before["cpu-probe-"]
            })
            .unwrap();
        assert!(t.join().unwrap());
    }
}
