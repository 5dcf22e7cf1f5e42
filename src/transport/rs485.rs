//! RS-485 direction control: on a UART wired to an RS-485 transceiver, the
//! kernel can raise RTS (the transceiver's driver enable) while a frame is
//! sent and drop it after the last stop bit, which is what a half-duplex
//! bus needs. USB adapters switch direction themselves and a pty has no
//! line at all: their drivers refuse the ioctl, and that is only a note.

use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;

use super::note::PortNote;

/// Linux `struct serial_rs485` (include/uapi/linux/serial.h): 32 bytes.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy)]
struct SerialRs485 {
    flags: u32,
    delay_rts_before_send: u32,
    delay_rts_after_send: u32,
    padding: [u32; 5],
}

/// `SER_RS485_ENABLED`: the driver controls direction.
const ENABLED: u32 = 1 << 0;
/// `SER_RS485_RTS_ON_SEND`: RTS high (driver enabled) while sending.
const RTS_ON_SEND: u32 = 1 << 1;
/// `SER_RS485_RTS_AFTER_SEND`: RTS high after sending (we want it low).
const RTS_AFTER_SEND: u32 = 1 << 2;

fn get(file: &File) -> io::Result<SerialRs485> {
    let mut conf = SerialRs485::default();
    // SAFETY: TIOCGRS485 writes one serial_rs485, which `conf` is.
    if unsafe { libc::ioctl(file.as_raw_fd(), libc::TIOCGRS485, &mut conf) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(conf)
}

fn set(file: &File, conf: &SerialRs485) -> io::Result<()> {
    // SAFETY: TIOCSRS485 reads one serial_rs485 (and may write it back).
    if unsafe { libc::ioctl(file.as_raw_fd(), libc::TIOCSRS485, conf) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Turns RS-485 direction control on unless the port already has it (a
/// device-tree or `setserial` setup is kept as it is). Returns what to tell
/// the user; never fails the open.
pub(crate) fn enable(file: &File) -> Option<PortNote> {
    let unsupported = |error: io::Error| PortNote::IoctlUnsupported {
        what: "RS-485 mode (TIOCSRS485)",
        error: error.to_string(),
    };
    let current = match get(file) {
        Ok(conf) => conf,
        Err(e) => return Some(unsupported(e)),
    };
    if current.flags & ENABLED != 0 {
        return Some(PortNote::Rs485(format!(
            "RS-485 direction control already on (flags {:#x}), kept",
            current.flags
        )));
    }
    let wanted = SerialRs485 {
        flags: (current.flags | ENABLED | RTS_ON_SEND) & !RTS_AFTER_SEND,
        ..current
    };
    match set(file, &wanted) {
        Ok(()) => Some(PortNote::Rs485(
            "RS-485 direction control on (RTS high while sending)".into(),
        )),
        Err(e) => Some(unsupported(e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_struct_has_the_kernels_size() {
        assert_eq!(std::mem::size_of::<SerialRs485>(), 32);
    }

    #[test]
    fn a_pty_refuses_and_that_is_a_note() {
        let pty = nix::pty::openpty(None, None).expect("openpty");
        let slave = File::from(pty.slave);
        match enable(&slave) {
            Some(PortNote::IoctlUnsupported { what, .. }) => assert!(what.contains("RS-485")),
            other => panic!("a pty has no RS-485 mode: {other:?}"),
        }
    }
}
