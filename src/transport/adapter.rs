//! The USB-serial adapter between the host and the RS-485 line, as far as
//! it shapes timing, and how jointd finds out which one a port is.
//!
//! A pseudo-terminal or a UART delivers a byte the moment it is written or
//! received. A USB adapter does not:
//! - host bytes leave in the next USB (micro)frame: 1 ms at full speed,
//!   125 µs at high speed;
//! - received bytes wait in the chip until the host's next IN poll, and an
//!   FTDI chip holds them until 62 are buffered or its **latency timer**
//!   (16 ms by default, 1 ms once set) runs out (FTDI AN232B-04, "Data
//!   Throughput, Latency and Handshaking").
//!
//! Which adapter a port is comes from the config (`adapter = "ftdi:1"`) or
//! from sysfs: the USB vendor/product id of the device behind the tty, its
//! driver, and the FTDI latency timer, read back *after* jointd set
//! `ASYNC_LOW_LATENCY` (which the Linux FTDI driver turns into a 1 ms timer),
//! so what is reported is what is in effect.

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Data bytes in a full FTDI packet (64 bytes less the two status bytes).
pub const FTDI_PACKET_PAYLOAD: usize = 62;

/// USB full-speed frame period.
const FULL_SPEED_FRAME: Duration = Duration::from_millis(1);
/// USB high-speed microframe period.
const HIGH_SPEED_FRAME: Duration = Duration::from_micros(125);
/// The FTDI latency timer out of the box on Linux.
pub const FTDI_DEFAULT_LATENCY_MS: u32 = 16;

/// An adapter model, by what matters to timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AdapterModel {
    /// No USB in between (a pty, a SoC UART): bytes pass at once.
    Native,
    /// FTDI FT232R / FT231X (full speed) with its latency timer, ms.
    Ftdi { latency_ms: u32 },
    /// WCH CH340/CH341 (full speed, no settable timer).
    Ch340,
    /// Silicon Labs CP2102 (full speed, no settable timer).
    Cp2102,
    /// FTDI FT232H (high speed) with its latency timer, ms.
    Ft232h { latency_ms: u32 },
}

impl AdapterModel {
    /// `native`, `ftdi[:MS]`, `ch340`, `cp2102`, `ft232h[:MS]` (MS 1..=255,
    /// the FTDI timer's range; 16 when left out).
    pub fn parse(text: &str) -> Result<Self, String> {
        let text = text.trim();
        let (name, ms) = match text.split_once(':') {
            Some((n, ms)) => (n, Some(ms)),
            None => (text, None),
        };
        let latency = |ms: Option<&str>| -> Result<u32, String> {
            match ms {
                None => Ok(FTDI_DEFAULT_LATENCY_MS),
                Some(ms) => match ms.trim().parse::<u32>() {
                    Ok(v @ 1..=255) => Ok(v),
                    _ => Err(format!(
                        "adapter `{text}`: the latency timer is 1..=255 ms, got `{ms}`"
                    )),
                },
            }
        };
        let no_timer = |model| match ms {
            None => Ok(model),
            Some(_) => Err(format!("adapter `{name}` has no latency timer to set")),
        };
        match name {
            "native" => no_timer(Self::Native),
            "ftdi" => latency(ms).map(|latency_ms| Self::Ftdi { latency_ms }),
            "ch340" => no_timer(Self::Ch340),
            "cp2102" => no_timer(Self::Cp2102),
            "ft232h" => latency(ms).map(|latency_ms| Self::Ft232h { latency_ms }),
            other => Err(format!(
                "adapter `{other}` is not one of native, ftdi[:MS], ch340, cp2102, ft232h[:MS]"
            )),
        }
    }

    /// The USB frame period host writes and adapter releases are aligned to
    /// (`None` without USB).
    pub fn usb_frame(self) -> Option<Duration> {
        match self {
            Self::Native => None,
            Self::Ftdi { .. } | Self::Ch340 | Self::Cp2102 => Some(FULL_SPEED_FRAME),
            Self::Ft232h { .. } => Some(HIGH_SPEED_FRAME),
        }
    }

    /// Data bytes in the full packet a full-speed FTDI chip sends as soon
    /// as they are in (a 64-byte packet less two status bytes; AN232B-04),
    /// where only such packets can date what the chip received: its latency
    /// timer longer than the 1 ms frame. (FT232H's 125 µs microframes are
    /// finer than a host can read, and its packets are larger.)
    pub fn packet_payload(self) -> Option<usize> {
        match self {
            Self::Ftdi { latency_ms } if latency_ms > 1 => Some(FTDI_PACKET_PAYLOAD),
            _ => None,
        }
    }

    /// True when the chip hands a reply to the host at the USB frame after
    /// it came in (no latency timer holds it).
    pub fn replies_next_frame(self) -> bool {
        self.latency_timer().is_none()
    }

    /// The FTDI latency timer, for the chips that have one.
    pub fn latency_timer(self) -> Option<Duration> {
        match self {
            Self::Ftdi { latency_ms } | Self::Ft232h { latency_ms } => {
                Some(Duration::from_millis(u64::from(latency_ms)))
            }
            _ => None,
        }
    }

    /// The longest a reply (less than 62 bytes) may sit between the wire and
    /// the host: the latency timer, or one poll, plus the frame in which
    /// the host's next IN poll lands.
    pub fn reply_hold(self) -> Duration {
        let frame = self.usb_frame().unwrap_or_default();
        self.latency_timer().unwrap_or(frame) + frame
    }

    /// The most a host write waits before its first byte is on the wire.
    pub fn write_hold(self) -> Duration {
        self.usb_frame().unwrap_or_default()
    }

    /// The shortest cycle of `broadcasts` control frames and one poll with
    /// its reply this adapter allows: a wire-timed pipeline writing one USB
    /// transfer per cycle, `T = P·⌈((B + 2)·tf + ta) / P⌉` (P the USB frame
    /// period, tf the frame time, ta the turnaround); on a native line the
    /// wire alone, `(B + 2)·tf + ta`. The bound the bench's ratios use.
    pub fn cycle_bound(self, frame: Duration, turnaround: Duration, broadcasts: u32) -> Duration {
        let wire = frame * (broadcasts + 2) + turnaround;
        match self.usb_frame() {
            None => wire,
            Some(p) => {
                let frames = wire.as_nanos().div_ceil(p.as_nanos().max(1));
                p * u32::try_from(frames).unwrap_or(u32::MAX)
            }
        }
    }

    /// True when a transaction's round trip is dominated by the adapter,
    /// not the wire: worth putting several frames in one write.
    pub fn is_latent(self) -> bool {
        self != Self::Native
    }
}

impl fmt::Display for AdapterModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Native => f.write_str("native"),
            Self::Ftdi { latency_ms } => write!(f, "ftdi:{latency_ms}"),
            Self::Ch340 => f.write_str("ch340"),
            Self::Cp2102 => f.write_str("cp2102"),
            Self::Ft232h { latency_ms } => write!(f, "ft232h:{latency_ms}"),
        }
    }
}

/// What the port turned out to be, and from what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdapterInfo {
    pub model: AdapterModel,
    /// How it was found: `"usb 0403:6001 (ftdi_sio)"`, `"no USB device (pty or UART)"`.
    pub found_by: String,
    /// A tty with no USB device behind it (a pty or a UART): a write
    /// reaches the line whenever that path passes it on, not within a USB
    /// frame as an adapter takes it.
    pub tty_without_usb: bool,
    /// A USB device was found behind the tty.
    pub usb: bool,
}

/// Finds the adapter behind `tty` (a `/dev` path, links followed) from
/// sysfs. Run after the port was opened and set up, so an FTDI latency timer
/// reads what is in effect.
pub fn detect(tty: &Path) -> AdapterInfo {
    let name = std::fs::canonicalize(tty)
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()));
    match name {
        Some(name) => detect_in(Path::new("/sys/class/tty"), &name),
        None => AdapterInfo {
            model: AdapterModel::Native,
            found_by: "not a device node: taken for native".into(),
            tty_without_usb: false,
            usb: false,
        },
    }
}

/// [`detect`] against a sysfs tty class directory (a fake one in tests).
pub fn detect_in(class_tty: &Path, name: &str) -> AdapterInfo {
    let device = class_tty.join(name).join("device");
    let Some(usb) = usb_device_dir(&device) else {
        return AdapterInfo {
            model: AdapterModel::Native,
            found_by: "no USB device behind the tty (a pty or a UART)".into(),
            tty_without_usb: true,
            usb: false,
        };
    };
    let id = |f: &str| {
        std::fs::read_to_string(usb.join(f))
            .map(|s| s.trim().to_ascii_lowercase())
            .unwrap_or_default()
    };
    let (vid, pid) = (id("idVendor"), id("idProduct"));
    let driver = std::fs::canonicalize(device.join("driver"))
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_default();
    let latency_ms = std::fs::read_to_string(device.join("latency_timer"))
        .ok()
        .and_then(|s| s.trim().parse::<u32>().ok())
        .unwrap_or(FTDI_DEFAULT_LATENCY_MS);
    let model = match (vid.as_str(), pid.as_str(), driver.as_str()) {
        ("0403", "6014", _) => AdapterModel::Ft232h { latency_ms },
        ("0403", _, _) | (_, _, "ftdi_sio") => AdapterModel::Ftdi { latency_ms },
        ("1a86", _, _) | (_, _, "ch341-uart" | "ch341") => AdapterModel::Ch340,
        ("10c4", _, _) | (_, _, "cp210x") => AdapterModel::Cp2102,
        // Another USB adapter: at least one USB frame each way.
        _ => AdapterModel::Ch340,
    };
    AdapterInfo {
        model,
        found_by: format!("usb {vid}:{pid} ({driver})"),
        tty_without_usb: false,
        usb: true,
    }
}

/// The USB device directory (the one with `idVendor`) above a tty's sysfs
/// `device` link, if the tty is behind USB.
pub(crate) fn usb_device_dir(device: &Path) -> Option<PathBuf> {
    let mut dir = std::fs::canonicalize(device).ok()?;
    for _ in 0..6 {
        if dir.join("idVendor").is_file() {
            return Some(dir);
        }
        dir = dir.parent()?.to_path_buf();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_parse_and_print_back() {
        for text in ["native", "ftdi:16", "ftdi:1", "ch340", "cp2102", "ft232h:1"] {
            let m = AdapterModel::parse(text).expect(text);
            assert_eq!(m.to_string(), text);
        }
        assert_eq!(
            AdapterModel::parse("ftdi"),
            Ok(AdapterModel::Ftdi { latency_ms: 16 })
        );
        assert!(AdapterModel::parse("ftdi:0")
            .unwrap_err()
            .contains("1..=255"));
        assert!(AdapterModel::parse("ch340:2")
            .unwrap_err()
            .contains("no latency timer"));
        assert!(AdapterModel::parse("pl2303")
            .unwrap_err()
            .contains("not one of"));
    }

    #[test]
    fn replies_are_held_by_the_timer_or_one_frame() {
        let ms = Duration::from_millis;
        assert_eq!(AdapterModel::Native.reply_hold(), Duration::ZERO);
        assert_eq!(AdapterModel::Ftdi { latency_ms: 16 }.reply_hold(), ms(17));
        assert_eq!(AdapterModel::Ch340.reply_hold(), ms(2));
        assert_eq!(
            AdapterModel::Ft232h { latency_ms: 1 }.reply_hold(),
            Duration::from_micros(1125)
        );
        assert!(!AdapterModel::Native.is_latent() && AdapterModel::Cp2102.is_latent());
    }

    #[test]
    fn cycle_bounds_match_the_issue_table() {
        let (tf, ta) = (Duration::from_micros(400), Duration::from_micros(100));
        // Idle polling (no broadcasts): 1111/s native; one poll per 1 ms frame.
        let idle = |m: AdapterModel| 1.0 / m.cycle_bound(tf, ta, 0).as_secs_f64();
        assert!((idle(AdapterModel::Native) - 1111.1).abs() < 0.2);
        assert!((idle(AdapterModel::Ch340) - 1000.0).abs() < 1e-6);
        // Two broadcasts and a poll: 500 cycles/s on full speed, 571 on FT232H.
        let with = |m: AdapterModel| 1.0 / m.cycle_bound(tf, ta, 2).as_secs_f64();
        assert!((with(AdapterModel::Ftdi { latency_ms: 16 }) - 500.0).abs() < 1e-6);
        assert!((with(AdapterModel::Ft232h { latency_ms: 1 }) - 571.43).abs() < 0.01);
    }

    /// A fake sysfs: class/tty/NAME/device -> devices/usb/1-1/1-1:1.0/NAME,
    /// the USB device (idVendor, idProduct) two levels up, a driver link.
    fn fake_sysfs(
        root: &Path,
        name: &str,
        ids: Option<(&str, &str)>,
        driver: &str,
        latency: Option<u32>,
    ) {
        let iface = root.join("devices/usb/1-1/1-1:1.0");
        let dev = iface.join(name);
        std::fs::create_dir_all(&dev).unwrap();
        std::fs::create_dir_all(root.join("class/tty").join(name)).unwrap();
        std::os::unix::fs::symlink(&dev, root.join("class/tty").join(name).join("device")).unwrap();
        let drv = root.join("bus/usb-serial/drivers").join(driver);
        std::fs::create_dir_all(&drv).unwrap();
        std::os::unix::fs::symlink(&drv, dev.join("driver")).unwrap();
        if let Some((v, p)) = ids {
            std::fs::write(root.join("devices/usb/1-1/idVendor"), format!("{v}\n")).unwrap();
            std::fs::write(root.join("devices/usb/1-1/idProduct"), format!("{p}\n")).unwrap();
        }
        if let Some(ms) = latency {
            std::fs::write(dev.join("latency_timer"), format!("{ms}\n")).unwrap();
        }
    }

    #[test]
    fn sysfs_says_which_adapter_and_its_timer() {
        let cases = [
            (Some(("0403", "6001")), "ftdi_sio", Some(1), "ftdi:1"),
            (Some(("0403", "6015")), "ftdi_sio", Some(16), "ftdi:16"),
            (Some(("0403", "6014")), "ftdi_sio", Some(2), "ft232h:2"),
            (Some(("1a86", "7523")), "ch341-uart", None, "ch340"),
            (Some(("10c4", "EA60")), "cp210x", None, "cp2102"),
            (None, "serial8250", None, "native"),
        ];
        for (i, (ids, driver, latency, want)) in cases.into_iter().enumerate() {
            let root =
                std::env::temp_dir().join(format!("jointd-sysfs-{}-{i}", std::process::id()));
            let _ = std::fs::remove_dir_all(&root);
            fake_sysfs(&root, "ttyUSB0", ids, driver, latency);
            let info = detect_in(&root.join("class/tty"), "ttyUSB0");
            assert_eq!(info.model.to_string(), want, "{info:?}");
            let _ = std::fs::remove_dir_all(&root);
        }
        let nowhere = detect_in(Path::new("/nonexistent"), "pts0");
        assert_eq!(nowhere.model, AdapterModel::Native);
    }
}
