//! Who changed what: every motion and configuration command a front-end
//! passed on, with the name of the token it came with (never the token),
//! logged and put in the events of the buses it concerns, so a recording
//! shows who moved what. A command repeated fast (targets at teleop rates)
//! is told once per second per sender and kind of command, with how many
//! more came in that second.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::bus::handle::BusEvent;
use crate::bus::BusHandle;

/// How often one sender's commands of one kind are told.
const WINDOW: Duration = Duration::from_secs(1);

/// The windows of the commands told lately, by (sender, kind).
#[derive(Debug, Default)]
pub(crate) struct Audit {
    told: Mutex<HashMap<(String, String), Told>>,
}

#[derive(Debug, Clone, Copy)]
struct Told {
    at: Instant,
    held_back: u64,
}

/// One command, as a front-end passes it on.
#[derive(Debug, Clone)]
pub(crate) struct Command<'a> {
    /// The token's name.
    pub(crate) by: &'a str,
    /// What kind of command, for collapsing repeats (`PUT
    /// /api/v1/buses/{bus}/devices/{id}/target`, `websocket setpoints`).
    pub(crate) kind: &'a str,
    /// The command as sent (`PUT /api/v1/buses/sim0/devices/1/target`).
    pub(crate) what: &'a str,
    /// How it ended.
    pub(crate) outcome: &'a str,
}

impl Audit {
    /// Tells `cmd` to the log and to `buses`' events, unless one like it
    /// was told less than a second ago (then it is counted, and told with
    /// the next).
    pub(crate) fn tell<'b>(&self, cmd: &Command<'_>, buses: impl Iterator<Item = &'b BusHandle>) {
        let now = Instant::now();
        let repeats = {
            let mut told = self.told.lock().unwrap_or_else(|p| p.into_inner());
            let key = (cmd.by.to_owned(), cmd.kind.to_owned());
            match told.get_mut(&key) {
                Some(t) if now.duration_since(t.at) < WINDOW => {
                    t.held_back += 1;
                    return;
                }
                Some(t) => {
                    let held = t.held_back;
                    *t = Told {
                        at: now,
                        held_back: 0,
                    };
                    held
                }
                None => {
                    told.insert(
                        key,
                        Told {
                            at: now,
                            held_back: 0,
                        },
                    );
                    0
                }
            }
        };
        tracing::info!(
            by = cmd.by,
            command = cmd.what,
            outcome = cmd.outcome,
            repeats,
            "command"
        );
        for bus in buses {
            bus.shared().emit(BusEvent::Command {
                bus: bus.name().to_owned(),
                by: cmd.by.to_owned(),
                command: cmd.what.to_owned(),
                outcome: cmd.outcome.to_owned(),
                repeats,
            });
        }
    }
}
