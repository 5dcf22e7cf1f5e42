//! `jointd doctor`'s flags, and the options a run takes (tests build
//! [`Options`] directly).

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;

use crate::bus::config::{Timing, FACTORY_BAUD};
use crate::protocol::ids::parse_id_list;
use crate::protocol::BaudLevel;

use super::port::Roots;

/// Arguments of `jointd doctor`.
#[derive(Args, Debug, Clone)]
pub struct DoctorArgs {
    /// The port: a `/dev/serial/by-id/…` link, `/dev/ttyUSB0`, a board
    /// UART, a pty.
    pub path: PathBuf,
    /// The baud to try first (500000, 230400, 115200, 38400, 19200); when
    /// nothing answers there, the others are tried in turn. Default: the
    /// modules' factory 230400.
    #[arg(long)]
    pub baud: Option<u32>,
    /// The whole report as JSON on stdout, for a bug report.
    #[arg(long)]
    pub json: bool,
    /// The ids to scan, e.g. `1-16` (fewer ids, a shorter scan; a whole
    /// scan at 19200 baud takes about 4 s).
    #[arg(long, default_value = "1-159")]
    pub ids: String,
    /// Reads per device in its burst.
    #[arg(long, default_value_t = 50)]
    pub burst: u32,
    /// Writes watched for the adapter's output count.
    #[arg(long, default_value_t = 64)]
    pub writes: u32,
    /// How long to listen to the idle line before sending anything, ms.
    #[arg(long, default_value_t = 500)]
    pub listen_ms: u64,
}

/// What one run of the doctor does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Options {
    /// The baud tried first.
    pub baud: u32,
    /// It was asked for (a scan that finds the devices elsewhere then fails).
    pub baud_given: bool,
    /// The ids scanned.
    pub ids: Vec<u8>,
    pub burst: u32,
    pub writes: u32,
    pub listen: Duration,
    /// How long past its modelled time a reply is waited for: the
    /// daemon's default (`timing.reply_margin_us`); tests on a loaded
    /// machine's pty give more.
    pub reply_margin: Duration,
    /// Where `/sys`, `/dev`, `/proc` and `/etc` are.
    pub roots: Roots,
}

impl Options {
    /// The command line's defaults, with `baud` tried first (the factory
    /// 230400 when `None`).
    pub fn new(baud: Option<u32>) -> Self {
        Self {
            baud: baud.unwrap_or(FACTORY_BAUD),
            baud_given: baud.is_some(),
            ids: (crate::protocol::MIN_DEVICE_ID..=crate::protocol::MAX_DEVICE_ID).collect(),
            burst: 50,
            writes: 64,
            listen: Duration::from_millis(500),
            reply_margin: Duration::from_micros(Timing::default().reply_margin_us),
            roots: Roots::default(),
        }
    }
}

impl DoctorArgs {
    /// The options the flags ask for; a baud no module speaks or a bad id
    /// list is refused, saying why.
    pub fn options(&self) -> Result<Options, String> {
        if let Some(b) = self.baud.filter(|b| BaudLevel::from_baud(*b).is_none()) {
            return Err(format!(
                "baud {b} is not one the modules speak (500000, 230400, 115200, 38400, 19200)"
            ));
        }
        let mut ids = parse_id_list(&self.ids)?;
        ids.sort_unstable();
        ids.dedup();
        Ok(Options {
            ids,
            burst: self.burst,
            writes: self.writes,
            listen: Duration::from_millis(self.listen_ms),
            ..Options::new(self.baud)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(baud: Option<u32>, ids: &str) -> DoctorArgs {
        DoctorArgs {
            path: "/dev/ttyUSB0".into(),
            baud,
            json: false,
            ids: ids.into(),
            burst: 50,
            writes: 64,
            listen_ms: 500,
        }
    }

    #[test]
    fn the_factory_baud_is_tried_first_unless_one_is_given() {
        let o = args(None, "1-159").options().expect("options");
        assert_eq!((o.baud, o.baud_given, o.ids.len()), (230_400, false, 159));
        let o = args(Some(500_000), "3,1-2,2").options().expect("options");
        assert_eq!(
            (o.baud, o.baud_given, o.ids),
            (500_000, true, vec![1, 2, 3])
        );
        assert!(args(Some(9600), "1")
            .options()
            .unwrap_err()
            .contains("9600"));
        assert!(args(None, "0").options().is_err());
    }
}
