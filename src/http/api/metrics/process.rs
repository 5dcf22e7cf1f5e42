//! The `process_*` families, named as Prometheus' client libraries name
//! them (so the usual dashboards and alerts work): CPU time, memory, file
//! descriptors and start time, read from Linux's `/proc/self` at each
//! scrape. A file that cannot be read or parsed leaves its families out;
//! it never fails the scrape.
//!
//! Parsing is pure (text in, numbers out) and tested on fixed text; only
//! [`families`] reads files.

use super::exposition::Exposition;

/// The fields of `/proc/self/stat` used here, in its own units.
#[derive(Debug, PartialEq)]
struct Stat {
    /// User plus system CPU time, clock ticks.
    cpu_ticks: u64,
    /// When the process started, clock ticks after boot.
    start_ticks: u64,
    vsize_bytes: u64,
    rss_pages: u64,
}

/// `/proc/[pid]/stat` (proc(5)). The command name, field 2, is in
/// parentheses and may hold spaces and parentheses itself: fields are
/// counted from the last `)`, where field 3 starts.
fn parse_stat(text: &str) -> Option<Stat> {
    let (_, rest) = text.rsplit_once(')')?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // Field n (1-based, as proc(5) numbers them) is fields[n - 3].
    let field = |n: usize| fields.get(n - 3)?.parse::<u64>().ok();
    Some(Stat {
        cpu_ticks: field(14)?.checked_add(field(15)?)?,
        start_ticks: field(22)?,
        vsize_bytes: field(23)?,
        rss_pages: field(24)?,
    })
}

/// Boot time, seconds since the epoch: the `btime` line of `/proc/stat`.
fn parse_btime(text: &str) -> Option<u64> {
    text.lines()
        .find_map(|l| l.strip_prefix("btime "))?
        .trim()
        .parse()
        .ok()
}

/// The soft limit of `Max open files` in `/proc/self/limits`; `None` when
/// it is `unlimited` (no number to report).
fn parse_max_open_files(text: &str) -> Option<u64> {
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("Max open files"))?;
    line.split_whitespace().next()?.parse().ok()
}

/// A `sysconf(3)` value, `None` if the system has none.
fn sysconf(name: libc::c_int) -> Option<u64> {
    // SAFETY: sysconf reads a system constant; it has no preconditions and
    // touches no memory of ours.
    let v = unsafe { libc::sysconf(name) };
    u64::try_from(v).ok().filter(|v| *v > 0)
}

pub(super) fn families(m: &mut Exposition) {
    let ticks = sysconf(libc::_SC_CLK_TCK);
    if let Some(stat) = read("/proc/self/stat").and_then(|t| parse_stat(&t)) {
        stat_families(m, &stat, ticks);
    }
    if let Ok(fds) = std::fs::read_dir("/proc/self/fd") {
        m.gauge(
            "process_open_fds",
            "Number of open file descriptors.",
            "",
            fds.count() as f64,
        );
    }
    if let Some(max) = read("/proc/self/limits").and_then(|t| parse_max_open_files(&t)) {
        m.gauge(
            "process_max_fds",
            "Maximum number of open file descriptors (the soft limit).",
            "",
            max as f64,
        );
    }
}

fn read(path: &str) -> Option<String> {
    std::fs::read_to_string(path).ok()
}

/// The families of `/proc/self/stat`. Those in clock ticks need the tick
/// rate; without it they are left out rather than guessed.
fn stat_families(m: &mut Exposition, stat: &Stat, ticks: Option<u64>) {
    if let Some(hz) = ticks {
        m.counter(
            "process_cpu_seconds_total",
            "Total user and system CPU time spent in seconds.",
            "",
            stat.cpu_ticks as f64 / hz as f64,
        );
        if let Some(btime) = read("/proc/stat").and_then(|t| parse_btime(&t)) {
            m.gauge(
                "process_start_time_seconds",
                "Start time of the process since unix epoch in seconds.",
                "",
                btime as f64 + stat.start_ticks as f64 / hz as f64,
            );
        }
    }
    m.gauge(
        "process_virtual_memory_bytes",
        "Virtual memory size in bytes.",
        "",
        stat.vsize_bytes as f64,
    );
    if let Some(page) = sysconf(libc::_SC_PAGESIZE) {
        m.gauge(
            "process_resident_memory_bytes",
            "Resident memory size in bytes.",
            "",
            stat.rss_pages.saturating_mul(page) as f64,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A real line, its command name made awkward: spaces and a `)`.
    const STAT: &str = "4242 (jointd (a) b) S 1 4242 4242 0 -1 4194560 2590 0 0 0 \
        150 37 0 0 20 0 9 0 123456 812345344 4321 18446744073709551615 1 1 0 0 0 0 0 \
        4096 1260 0 0 0 17 1 0 0 0 0 0\n";

    #[test]
    fn stat_fields_count_from_the_last_parenthesis() {
        assert_eq!(
            parse_stat(STAT),
            Some(Stat {
                cpu_ticks: 187,
                start_ticks: 123456,
                vsize_bytes: 812345344,
                rss_pages: 4321,
            })
        );
    }

    #[test]
    fn a_short_or_garbled_stat_is_none() {
        assert_eq!(parse_stat("4242 (jointd) S 1 2 3"), None);
        assert_eq!(parse_stat("no parenthesis at all"), None);
        assert_eq!(parse_stat(&STAT.replace(" 150 ", " x ")), None);
    }

    #[test]
    fn btime_and_the_open_files_limit() {
        let proc_stat = "cpu  1 2 3 4\nintr 5\nbtime 1718000000\nprocesses 99\n";
        assert_eq!(parse_btime(proc_stat), Some(1_718_000_000));
        assert_eq!(parse_btime("cpu 1 2\n"), None);
        let limits =
            "Limit                     Soft Limit           Hard Limit           Units     \n\
            Max processes             63392                63392                processes \n\
            Max open files            1024                 524288               files     \n";
        assert_eq!(parse_max_open_files(limits), Some(1024));
        let unlimited = limits.replace("1024  ", "unlimited");
        assert_eq!(parse_max_open_files(&unlimited), None);
    }
}
