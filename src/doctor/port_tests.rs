use super::*;
use std::os::unix::fs::symlink;

/// A fake system: an FTDI adapter as ttyUSB0 with a by-id link, and an
/// 8250 port ttyS1 with no UART.
fn fake(root: &Path) -> Roots {
    let _ = fs::remove_dir_all(root);
    let usb = root.join("sys/devices/usb/1-1");
    let port = usb.join("1-1:1.0/ttyUSB0");
    fs::create_dir_all(&port).unwrap();
    for (f, v) in [
        ("idVendor", "0403"),
        ("idProduct", "6001"),
        ("serial", "A10K1234"),
        ("manufacturer", "FTDI"),
        ("product", "FT232R USB UART"),
    ] {
        fs::write(usb.join(f), format!("{v}\n")).unwrap();
    }
    fs::write(port.join("latency_timer"), "16\n").unwrap();
    let driver = root.join("sys/bus/usb-serial/drivers/ftdi_sio");
    fs::create_dir_all(&driver).unwrap();
    symlink(&driver, port.join("driver")).unwrap();
    let class = root.join("sys/class/tty");
    fs::create_dir_all(class.join("ttyUSB0")).unwrap();
    symlink(&port, class.join("ttyUSB0/device")).unwrap();
    let s1 = root.join("sys/devices/platform/serial8250/tty/ttyS1");
    fs::create_dir_all(&s1).unwrap();
    fs::create_dir_all(class.join("ttyS1")).unwrap();
    symlink(&s1, class.join("ttyS1/device")).unwrap();
    fs::write(class.join("ttyS1/type"), "0\n").unwrap();
    let by_id = root.join("dev/serial/by-id");
    fs::create_dir_all(&by_id).unwrap();
    fs::create_dir_all(root.join("dev/pts")).unwrap();
    for node in ["ttyUSB0", "ttyS1", "pts/3"] {
        fs::write(root.join("dev").join(node), "").unwrap();
    }
    symlink(
        root.join("dev/ttyUSB0"),
        by_id.join("usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"),
    )
    .unwrap();
    Roots {
        sys: root.join("sys"),
        dev: root.join("dev"),
        proc_root: root.join("proc"),
        etc: root.join("etc"),
    }
}

fn tree(name: &str) -> (PathBuf, Roots) {
    // Canonical, so that a node named by its path is its device.
    let tmp = fs::canonicalize(std::env::temp_dir()).expect("a temp dir");
    let root = tmp.join(format!("jointd-doctor-{name}-{}", std::process::id()));
    let roots = fake(&root);
    (root, roots)
}

#[test]
fn a_usb_adapter_is_named_with_its_ids_serial_and_by_id_link() {
    let (root, roots) = tree("usb");
    let facts = inspect(&roots.dev.join("ttyUSB0"), &roots);
    let PortKind::Usb(u) = &facts.kind else {
        panic!("not USB: {facts:?}")
    };
    assert_eq!(
        (u.vid.as_str(), u.pid.as_str(), u.driver.as_str()),
        ("0403", "6001", "ftdi_sio")
    );
    assert_eq!(u.serial.as_deref(), Some("A10K1234"));
    assert_eq!(facts.latency_timer_ms, Some(16));
    assert_eq!(facts.by_id.len(), 1);
    let c = kind_check(&facts);
    assert!(
        c.found
            .contains("0403:6001 FTDI FT232R USB UART (ftdi_sio), serial A10K1234"),
        "{}",
        c.found
    );
    // Named by its node: the by-id link is the fix.
    let s = stable_path_check(&facts);
    assert_eq!(s.verdict, super::super::check::Verdict::Warn);
    assert!(s.fix.unwrap_or_default().contains("by-id/usb-FTDI"));
    // Named by the link: fine.
    let linked = inspect(&facts.by_id[0], &roots);
    assert_eq!(
        stable_path_check(&linked).verdict,
        super::super::check::Verdict::Ok
    );
    let _ = fs::remove_dir_all(root);
}

#[test]
fn a_pty_a_phantom_uart_and_a_missing_path_are_told_apart() {
    let (root, roots) = tree("kinds");
    assert_eq!(
        inspect(&roots.dev.join("pts/3"), &roots).kind,
        PortKind::Pty
    );
    let s1 = inspect(&roots.dev.join("ttyS1"), &roots);
    assert!(
        matches!(&s1.kind, PortKind::Uart { present: false, .. }),
        "{s1:?}"
    );
    assert_eq!(kind_check(&s1).verdict, super::super::check::Verdict::Fail);
    let none = inspect(&roots.dev.join("ttyUSB9"), &roots);
    assert_eq!(
        (none.kind.clone(), none.device.clone()),
        (PortKind::Unknown, None)
    );
    let _ = fs::remove_dir_all(root);
}

#[test]
fn the_udev_rule_names_the_adapter_and_its_group() {
    let u = UsbFacts {
        vid: "1a86".into(),
        pid: "7523".into(),
        driver: "ch341-uart".into(),
        serial: None,
        manufacturer: None,
        product: None,
    };
    let rule = udev_rule(&u);
    assert!(
        rule.contains("ATTRS{idVendor}==\"1a86\", ATTRS{idProduct}==\"7523\", SYMLINK"),
        "{rule}"
    );
    assert!(rule.contains("GROUP=\"dialout\""), "{rule}");
}
