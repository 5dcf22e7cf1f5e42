//! The value of `--foxglove` and of `foxglove =` in the config file: where
//! the live view listens. A bare port is loopback (`8765` is
//! `127.0.0.1:8765`): Foxglove's protocol has no authentication, so
//! listening beyond this host has to be spelt out as an address. Pure.

use std::net::{Ipv4Addr, SocketAddr};

/// `PORT` (on loopback) or `IP:PORT` / `[IPv6]:PORT` (bound as given).
pub fn parse_addr(text: &str) -> Result<SocketAddr, String> {
    let text = text.trim();
    if let Ok(port) = text.parse::<u16>() {
        return Ok(SocketAddr::from((Ipv4Addr::LOCALHOST, port)));
    }
    text.parse::<SocketAddr>().map_err(|_| {
        format!(
            "`{text}` is neither a port (8765: on loopback) nor an IP address with a port \
             (127.0.0.1:8765, [::1]:8765, 0.0.0.0:8765)"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bare_port_is_loopback_and_an_address_binds_as_given() {
        assert_eq!(parse_addr("8765").unwrap().to_string(), "127.0.0.1:8765");
        assert_eq!(parse_addr(" 0 ").unwrap().to_string(), "127.0.0.1:0");
        assert_eq!(
            parse_addr("0.0.0.0:9000").unwrap().to_string(),
            "0.0.0.0:9000"
        );
        assert_eq!(parse_addr("[::1]:8765").unwrap().to_string(), "[::1]:8765");
        for bad in [
            "",
            "localhost:8765",
            "65536",
            "127.0.0.1",
            "ws://127.0.0.1:8765",
        ] {
            let err = parse_addr(bad).unwrap_err();
            assert!(err.contains("neither a port"), "{bad}: {err}");
        }
    }
}
