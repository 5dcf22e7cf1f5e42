use super::*;
use nix::pty::openpty;

fn slave_path(slave: &std::os::fd::OwnedFd) -> PathBuf {
    std::fs::read_link(format!("/proc/self/fd/{}", slave.as_raw_fd())).expect("pty slave path")
}

#[test]
fn a_count_that_cannot_be_read_or_is_negative_says_nothing_was_taken() {
    assert_eq!(untaken(Ok(12)), 12);
    assert_eq!(untaken(Ok(0)), 0);
    assert_eq!(untaken(Ok(-1)), usize::MAX);
    assert_eq!(
        untaken(Err(io::Error::from_raw_os_error(libc::EIO))),
        usize::MAX
    );
}

#[test]
fn bytes_a_failed_write_never_passed_on_are_not_counted_unsent() {
    let pty = openpty(None, None).expect("openpty");
    let path = slave_path(&pty.slave);
    let count = std::sync::Arc::new(TakenCount::default());
    let (port, _) = TtyPort::open(&path, 500_000).expect("open pty slave");
    let mut port = port.counted_by(count);
    // The simulator's end goes away: the write fails.
    drop(pty.master);
    assert!(port.write_all(&[1, 2, 3]).is_err());
    assert_eq!(port.unsent(), Some(0), "a write that never left");
}

#[test]
fn pty_master_sees_the_baud_the_host_set() {
    let pty = openpty(None, None).expect("openpty");
    let path = slave_path(&pty.slave);
    let (mut port, _notes) = TtyPort::open(&path, 230_400).expect("open pty slave");
    assert_eq!(read_baud(pty.master.as_fd()).unwrap(), Some(230_400));
    port.set_baud(500_000).unwrap();
    assert_eq!(read_baud(pty.master.as_fd()).unwrap(), Some(500_000));
}

#[test]
fn bytes_cross_a_pty_and_reads_time_out() {
    let pty = openpty(None, None).expect("openpty");
    make_raw(pty.master.as_fd(), 500_000).unwrap();
    let path = slave_path(&pty.slave);
    let (mut port, _) = TtyPort::open(&path, 500_000).expect("open pty slave");
    let mut master = File::from(pty.master);
    master.write_all(&[0x55, 0xAA]).unwrap();
    let mut buf = [0u8; 4];
    assert_eq!(
        port.read_timeout(&mut buf, Duration::from_millis(100))
            .unwrap(),
        2
    );
    assert_eq!(
        port.read_timeout(&mut buf, Duration::from_micros(300))
            .unwrap(),
        0
    );
    port.write_all(&[1, 2, 3]).unwrap();
    assert!(wait_readable(master.as_fd(), Duration::from_millis(100)).unwrap());
}

#[test]
fn an_exclusive_open_refuses_a_held_port_and_a_plain_one_does_not() {
    let pty = openpty(None, None).expect("openpty");
    let path = slave_path(&pty.slave);
    let locked = PortSetup {
        rs485: false,
        exclusive: true,
    };
    let (first, _) = TtyPort::open_with(&path, 500_000, locked).expect("first open");
    let err = TtyPort::open_with(&path, 230_400, locked).expect_err("held");
    assert!(is_held(&err), "{err}");
    assert!(err.to_string().contains("held by another process"), "{err}");
    // Refused before it was touched: the baud is the first open's.
    assert_eq!(read_baud(pty.master.as_fd()).unwrap(), Some(500_000));
    assert!(
        TtyPort::open(&path, 500_000).is_ok(),
        "a plain open ignores the lock"
    );
    drop(first);
    assert!(
        TtyPort::open_with(&path, 500_000, locked).is_ok(),
        "free again"
    );
}

#[test]
fn unknown_baud_is_refused() {
    assert!(to_termios_baud(9600).is_err());
}
