//! The doctor's checks of a configured bus ([`crate::doctor`]), run on
//! the port its owner lends between frames: refused while a joint is
//! enabled; the bus polls again once the run ends.

use std::time::Duration;

use crate::doctor::{self, Options, Report};

use super::error::ControlResult;
use super::state::Control;

/// The longest a run may take, waiting for the owner included: a scan of
/// every id at each of the five bauds when nothing answers at the bus's
/// own (about 4 s at 19200 baud alone), the bursts and the count's watch.
const DOCTOR_WITHIN: Duration = Duration::from_secs(60);

impl Control {
    /// Runs the doctor on bus `bus`'s port: the same report as
    /// `jointd doctor PATH`, its first baud and reply margin the bus's.
    pub(crate) async fn doctor(&self, bus: &str) -> ControlResult<Report> {
        let handle = self.bus(bus)?;
        let report = handle
            .lend_port(DOCTOR_WITHIN, |port, loan| {
                let options = Options {
                    baud_given: false,
                    reply_margin: loan.reply_margin,
                    ..Options::new(Some(loan.baud))
                };
                doctor::examine_lent(port, loan, &options)
            })
            .await?;
        Ok(report)
    }
}
