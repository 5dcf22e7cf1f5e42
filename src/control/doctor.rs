//! The doctor's checks of a configured bus ([`crate::doctor`]), run on
//! the port its owner lends between frames: refused while a joint is
//! enabled; the bus polls again once the run ends.

use std::time::Duration;

use crate::doctor::{self, Options, Report};

use super::error::{ControlError, ControlResult};
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
        let _turn = DoctorTurn::take(self, bus)?;
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

/// A bus's check under way: a second one is refused while it runs (each
/// pauses the bus's polling; a queue of them would keep it blind).
struct DoctorTurn<'a> {
    control: &'a Control,
    bus: String,
}

impl<'a> DoctorTurn<'a> {
    fn take(control: &'a Control, bus: &str) -> ControlResult<Self> {
        let mut running = control.doctoring.lock().unwrap_or_else(|p| p.into_inner());
        if !running.insert(bus.to_owned()) {
            return Err(ControlError::conflict(
                "doctor-running",
                "A check is running",
                format!(
                    "bus `{bus}` is being checked already; its report comes when that run ends"
                ),
            ));
        }
        Ok(Self {
            control,
            bus: bus.to_owned(),
        })
    }
}

impl Drop for DoctorTurn<'_> {
    fn drop(&mut self) {
        self.control
            .doctoring
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&self.bus);
    }
}
