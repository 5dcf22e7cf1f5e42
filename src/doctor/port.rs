//! What the port is, read from the filesystem before it is opened: the
//! device node behind the path; the USB device behind the tty (vendor and
//! product id, driver, serial number, product), or a pseudo-terminal, or a
//! board's UART; the `/dev/serial/by-id` links to it; the FTDI latency
//! timer as the system has it. Nothing here opens the port: every fact is
//! a file read under [`Roots`], so the tests build a fake tree.

use std::fs;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::check::{Check, CheckId};

/// Where the system's trees are (`/sys`, `/dev`, `/proc`, `/etc`): a
/// temporary directory in tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Roots {
    pub sys: PathBuf,
    pub dev: PathBuf,
    pub proc_root: PathBuf,
    pub etc: PathBuf,
}

impl Default for Roots {
    fn default() -> Self {
        Self {
            sys: "/sys".into(),
            dev: "/dev".into(),
            proc_root: "/proc".into(),
            etc: "/etc".into(),
        }
    }
}

/// The USB device behind a tty, as sysfs describes it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct UsbFacts {
    /// `0403`, lower case.
    pub vid: String,
    pub pid: String,
    /// The tty's driver: `ftdi_sio`, `ch341-uart`, `cp210x`.
    pub driver: String,
    pub serial: Option<String>,
    pub manufacturer: Option<String>,
    pub product: Option<String>,
}

/// What kind of tty the path leads to.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PortKind {
    Usb(UsbFacts),
    /// A pseudo-terminal: another program holds the other end.
    Pty,
    /// A UART of the board; `present: false` for a port its driver
    /// registered with no hardware behind it (an 8250 `ttyS*` of type 0).
    Uart {
        driver: String,
        present: bool,
    },
    /// No tty sysfs knows (a missing path, not a device node).
    Unknown,
}

/// Everything known of the port before opening it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PortFacts {
    /// As given.
    pub path: PathBuf,
    /// The device node, links followed (`None`: the path leads nowhere).
    pub device: Option<PathBuf>,
    /// The tty's name (`ttyUSB0`; `3` for `/dev/pts/3`).
    pub tty: Option<String>,
    pub kind: PortKind,
    /// `/dev/serial/by-id` links to the device: stable across replugs.
    pub by_id: Vec<PathBuf>,
    /// `/dev/serial/by-path` links: stable while it stays in one USB port.
    pub by_path: Vec<PathBuf>,
    /// The FTDI latency timer before jointd opened the port, ms.
    pub latency_timer_ms: Option<u32>,
    pub latency_timer_path: Option<PathBuf>,
    /// This user may write the timer (and so set it to 1 ms itself).
    pub latency_timer_writable: bool,
}

impl PortFacts {
    /// A port known by its path alone: nothing found of it yet.
    pub fn unknown(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            device: None,
            tty: None,
            kind: PortKind::Unknown,
            by_id: Vec::new(),
            by_path: Vec::new(),
            latency_timer_ms: None,
            latency_timer_path: None,
            latency_timer_writable: false,
        }
    }
}

/// Reads what the filesystem says of `path`.
pub fn inspect(path: &Path, roots: &Roots) -> PortFacts {
    let device = fs::canonicalize(path).ok();
    let tty = device
        .as_ref()
        .and_then(|d| d.file_name())
        .map(|n| n.to_string_lossy().into_owned());
    let kind = match (&device, &tty) {
        (Some(d), Some(t)) => kind_of(d, t, roots),
        _ => PortKind::Unknown,
    };
    let links = |sub: &str| match &device {
        Some(d) => links_to(&roots.dev.join("serial").join(sub), d),
        None => Vec::new(),
    };
    let timer = tty.as_deref().and_then(|t| latency_timer_file(t, roots));
    PortFacts {
        path: path.to_path_buf(),
        by_id: links("by-id"),
        by_path: links("by-path"),
        latency_timer_ms: timer
            .as_deref()
            .and_then(read_trimmed)
            .and_then(|s| s.parse().ok()),
        latency_timer_writable: timer.as_deref().is_some_and(writable),
        latency_timer_path: timer,
        device,
        tty,
        kind,
    }
}

fn kind_of(device: &Path, tty: &str, roots: &Roots) -> PortKind {
    let pts = fs::canonicalize(roots.dev.join("pts")).unwrap_or_else(|_| roots.dev.join("pts"));
    if device.starts_with(&pts) {
        return PortKind::Pty;
    }
    let class = roots.sys.join("class/tty").join(tty);
    let dev_dir = class.join("device");
    if !dev_dir.exists() {
        return PortKind::Unknown;
    }
    let driver = link_name(&dev_dir.join("driver")).unwrap_or_default();
    match crate::transport::adapter::usb_device_dir(&dev_dir) {
        Some(usb) => PortKind::Usb(usb_facts(&usb, driver)),
        None => PortKind::Uart {
            driver,
            // An 8250 port with no UART says `type` 0 (PORT_UNKNOWN).
            present: read_trimmed(&class.join("type")).map_or(true, |t| t != "0"),
        },
    }
}

fn usb_facts(usb: &Path, driver: String) -> UsbFacts {
    let text = |f: &str| read_trimmed(&usb.join(f)).filter(|s| !s.is_empty());
    UsbFacts {
        vid: text("idVendor").unwrap_or_default().to_ascii_lowercase(),
        pid: text("idProduct").unwrap_or_default().to_ascii_lowercase(),
        driver,
        serial: text("serial"),
        manufacturer: text("manufacturer"),
        product: text("product"),
    }
}

/// The timer of an FTDI tty: `/sys/bus/usb-serial/devices/TTY/latency_timer`
/// (the same file as under the tty's class `device`), if it has one.
fn latency_timer_file(tty: &str, roots: &Roots) -> Option<PathBuf> {
    [
        roots.sys.join("bus/usb-serial/devices").join(tty),
        roots.sys.join("class/tty").join(tty).join("device"),
    ]
    .into_iter()
    .map(|dir| dir.join("latency_timer"))
    .find(|f| f.is_file())
}

fn writable(path: &Path) -> bool {
    nix::unistd::access(path, nix::unistd::AccessFlags::W_OK).is_ok()
}

/// The entries of `dir` that lead to `target` (links followed), sorted.
pub(crate) fn links_to(dir: &Path, target: &Path) -> Vec<PathBuf> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut found: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| fs::canonicalize(p).is_ok_and(|c| c == target))
        .collect();
    found.sort();
    found
}

fn link_name(link: &Path) -> Option<String> {
    let target = fs::canonicalize(link).ok()?;
    Some(target.file_name()?.to_string_lossy().into_owned())
}

pub(crate) fn read_trimmed(path: &Path) -> Option<String> {
    fs::read_to_string(path).ok().map(|s| s.trim().to_string())
}

/// What the port is, in a sentence.
pub(crate) fn kind_check(facts: &PortFacts) -> Check {
    let id = CheckId::PortKind;
    match &facts.kind {
        PortKind::Usb(u) => Check::ok(id, describe_usb(u)),
        PortKind::Pty => Check::ok(
            id,
            "a pseudo-terminal: another program holds its other end (a simulator, \
             socat, a network serial bridge); no USB adapter of its own",
        ),
        PortKind::Uart {
            driver,
            present: true,
        } => Check::ok(id, format!("a UART of the board (driver: {})", or_none(driver))),
        PortKind::Uart { driver, .. } => Check::fail(
            id,
            format!(
                "a port with no UART behind it (sysfs type 0, driver: {})",
                or_none(driver)
            ),
            "pick the tty your RS-485 transceiver is wired to (`ls /sys/class/tty/*/device/driver`), \
             or a USB-RS485 adapter (`ls -l /dev/serial/by-id/`)",
        ),
        PortKind::Unknown => Check::warn(
            id,
            format!("no tty in sysfs behind {}", facts.path.display()),
            "name the adapter's device: `ls -l /dev/serial/by-id/` lists the USB ones",
        ),
    }
}

fn or_none(driver: &str) -> &str {
    if driver.is_empty() {
        "none bound"
    } else {
        driver
    }
}

/// `USB 0403:6001 FTDI FT232R USB UART (ftdi_sio), serial A10K1234`.
pub(crate) fn describe_usb(u: &UsbFacts) -> String {
    let mut text = format!("USB {}:{}", u.vid, u.pid);
    for part in [&u.manufacturer, &u.product].into_iter().flatten() {
        text.push(' ');
        text.push_str(part);
    }
    text.push_str(&format!(" ({})", u.driver));
    if let Some(serial) = &u.serial {
        text.push_str(&format!(", serial {serial}"));
    }
    text
}

/// Whether the path survives a replug, and the one to use if not.
pub(crate) fn stable_path_check(facts: &PortFacts) -> Check {
    let id = CheckId::StablePath;
    let Some(device) = &facts.device else {
        return Check::skipped(id, "the path leads nowhere (see `opens raw`)");
    };
    if facts.kind == PortKind::Pty {
        return Check::skipped(id, "a pty's path is its creator's to name");
    }
    if facts.path != *device {
        return Check::ok(
            id,
            format!(
                "{} is a link to {}: it follows the adapter",
                facts.path.display(),
                device.display()
            ),
        );
    }
    match (&facts.kind, facts.by_id.first()) {
        (_, Some(link)) => Check::warn(
            id,
            format!(
                "{} may be another adapter after a replug or a reboot",
                device.display()
            ),
            format!("put {} in the config", link.display()),
        ),
        (PortKind::Usb(u), None) => Check::warn(
            id,
            format!(
                "no /dev/serial/by-id link to {} (the adapter reports no serial number)",
                device.display()
            ),
            format!(
                "give it a name of its own with a udev rule (deploy/99-jointd.rules):\n{}",
                udev_rule(u)
            ),
        ),
        _ => Check::ok(
            id,
            format!("{}: a board UART keeps its name", device.display()),
        ),
    }
}

/// A udev rule that names the adapter `/dev/jointd-bus0`, for the
/// `dialout` group, read-write for it.
pub(crate) fn udev_rule(u: &UsbFacts) -> String {
    let serial = u
        .serial
        .as_ref()
        .map(|s| format!(", ATTRS{{serial}}==\"{s}\""))
        .unwrap_or_default();
    format!(
        "SUBSYSTEM==\"tty\", ATTRS{{idVendor}}==\"{}\", ATTRS{{idProduct}}==\"{}\"{serial}, \
         SYMLINK+=\"jointd-bus0\", GROUP=\"dialout\", MODE=\"0660\"",
        u.vid, u.pid
    )
}

#[cfg(test)]
#[path = "port_tests.rs"]
mod tests;
