//! Teleop streams: the joints one client (a WebSocket connection, the ROS 2
//! bridge) streams setpoints to, each under the motion epoch its stream
//! began with. When a joint's epoch moves on (an e-stop, a disable, a
//! reset, a fault, a mode change, an enable) its stream ends with that
//! reason and never resumes by itself: the client's next setpoints for it
//! are refused until it asks for a new stream (`restart`). A client that
//! streams on blindly through an e-stop and a later enable (from the
//! dashboard, say) therefore cannot drive the joint again unasked.

use std::collections::BTreeMap;
use std::time::Instant;

use super::batch::{self, BatchItem};
use super::error::{ControlError, ControlResult};
use super::joints::JointRef;
use super::state::Control;
use crate::bus::authority::{Epoch, Revoked};
use crate::bus::Source;
use crate::control::books::streams::Registration;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stream {
    Live(Epoch),
    Ended(Revoked),
}

/// What a teleop batch did once stored.
#[derive(Debug, Clone)]
pub(crate) struct Applied {
    /// When it was stored.
    pub accepted: Instant,
    /// (bus name, store sequence number) per bus it touched.
    pub writes: Vec<(String, u64)>,
    /// Its joints, bus by bus in the batch's order.
    pub joints: Vec<JointRef>,
}

/// One client's streams, by joint.
#[derive(Debug, Default)]
pub struct Streams {
    joints: BTreeMap<JointRef, Stream>,
    /// Where the dashboard reads who streams to what (none in unit tests).
    shown: Option<Registration>,
}

impl Streams {
    /// A client's streams, listed in the daemon's stream book while live.
    pub fn shown_as(registration: Registration) -> Self {
        Self {
            joints: BTreeMap::new(),
            shown: Some(registration),
        }
    }

    fn show(&self, sent: bool) {
        if let Some(r) = &self.shown {
            r.set_live(
                self.joints
                    .iter()
                    .filter(|(_, s)| matches!(s, Stream::Live(_)))
                    .map(|(j, _)| j.clone()),
                sent,
            );
        }
    }

    /// The last teleop step, the same for every front-end (WebSocket
    /// setpoints, ROS 2 joint commands, the LeRobot plugin over the
    /// WebSocket): the batch checked whole ([`batch::resolve`]), each joint
    /// admitted under its stream's epoch ([`Self::admit`]), then each bus's
    /// targets stored under those epochs as written by `source`. Nothing
    /// of a refused batch is stored.
    pub(crate) fn apply(
        &mut self,
        control: &Control,
        items: &[BatchItem],
        restart: bool,
        source: Source,
    ) -> ControlResult<Applied> {
        let per_bus = batch::resolve(control, items)?;
        let joints: Vec<JointRef> = per_bus
            .iter()
            .flat_map(|(name, targets)| {
                targets.iter().map(|(id, _)| JointRef {
                    bus: name.clone(),
                    id: *id,
                })
            })
            .collect();
        let mut epochs = self.admit(control, &joints, restart)?.into_iter();
        let accepted = Instant::now();
        let mut writes = Vec::with_capacity(per_bus.len());
        for (name, targets) in per_bus {
            let bus = control.bus(&name)?;
            let under: Vec<_> = targets
                .iter()
                .zip(epochs.by_ref())
                .map(|(&(id, sp), epoch)| (id, sp, epoch))
                .collect();
            writes.push((name, bus.set_targets_under(&under, source)));
        }
        Ok(Applied {
            accepted,
            writes,
            joints,
        })
    }

    /// The epoch each of `joints` streams under, in order: a joint's first
    /// setpoints (or any with `restart`) begin its stream under its current
    /// epoch. All or nothing: one ended stream refuses the batch.
    pub fn admit(
        &mut self,
        control: &Control,
        joints: &[JointRef],
        restart: bool,
    ) -> ControlResult<Vec<Epoch>> {
        let mut epochs = Vec::with_capacity(joints.len());
        for j in joints {
            let authority = control.bus(&j.bus)?.authority();
            let now = authority.grant(j.id).epoch;
            let stream = match self.joints.get(j) {
                Some(_) if restart => Stream::Live(now),
                None => Stream::Live(now),
                Some(Stream::Live(e)) if *e == now => Stream::Live(now),
                Some(Stream::Live(_)) => {
                    Stream::Ended(authority.last_revoked(j.id).unwrap_or(Revoked::Disabled))
                }
                Some(ended) => *ended,
            };
            match stream {
                Stream::Live(e) => epochs.push(e),
                Stream::Ended(why) => {
                    self.joints.insert(j.clone(), stream);
                    // Every other stream an epoch ended too, so none is
                    // still shown as live.
                    self.end_revoked(control);
                    self.show(false);
                    return Err(ended(j, why));
                }
            }
        }
        let began = joints
            .iter()
            .any(|j| !matches!(self.joints.get(j), Some(Stream::Live(_))));
        for (j, e) in joints.iter().zip(&epochs) {
            self.joints.insert(j.clone(), Stream::Live(*e));
        }
        if began {
            self.show(true);
        } else if let Some(r) = &self.shown {
            r.sent();
        }
        Ok(epochs)
    }

    /// Streams whose joint's epoch moved on since they began: each ends
    /// now, and is returned once with why.
    pub fn end_revoked(&mut self, control: &Control) -> Vec<(JointRef, Revoked)> {
        let mut out = Vec::new();
        for (j, stream) in self.joints.iter_mut() {
            let Stream::Live(e) = *stream else { continue };
            let Ok(bus) = control.bus(&j.bus) else {
                continue;
            };
            if bus.authority().grant(j.id).epoch != e {
                let why = bus
                    .authority()
                    .last_revoked(j.id)
                    .unwrap_or(Revoked::Disabled);
                *stream = Stream::Ended(why);
                out.push((j.clone(), why));
            }
        }
        if !out.is_empty() {
            self.show(false);
        }
        out
    }

    /// True while some stream is live (worth watching for its end).
    pub fn any_live(&self) -> bool {
        self.joints.values().any(|s| matches!(s, Stream::Live(_)))
    }
}

fn ended(j: &JointRef, why: Revoked) -> ControlError {
    ControlError::conflict(
        "stream-ended",
        "Setpoint stream ended",
        format!(
            "the setpoint stream to joint {} of bus `{}` ended ({}): send the next setpoints \
             with \"restart\": true to begin a new one",
            j.id,
            j.bus,
            why.name()
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::handle::{BusHandle, BusShared, BusSnapshot};
    use crate::control::limits::SoftLimits;

    fn control() -> Control {
        let shared = BusShared::new("b".into(), BusSnapshot::new("b", "/dev/null", 500_000));
        let (tx, _rx) = std::sync::mpsc::sync_channel(1);
        Control::new(vec![BusHandle::new(shared, tx)], SoftLimits::default())
    }

    fn enable(c: &Control, id: u8) {
        let authority = c.bus("b").expect("bus").authority();
        let epoch = authority.revoke(id, Revoked::Reenabled);
        assert!(authority.arm(id, epoch));
    }

    #[test]
    fn a_stream_ended_by_an_estop_stays_ended_until_restarted() {
        let c = control();
        let j = JointRef {
            bus: "b".into(),
            id: 1,
        };
        enable(&c, 1);
        let mut streams = Streams::default();
        let first = streams
            .admit(&c, std::slice::from_ref(&j), false)
            .expect("admitted");
        assert!(streams.any_live());
        c.bus("b")
            .expect("bus")
            .authority()
            .revoke_all(Revoked::Estopped);
        assert_eq!(
            streams.end_revoked(&c),
            vec![(j.clone(), Revoked::Estopped)]
        );
        assert!(streams.end_revoked(&c).is_empty(), "said once");
        enable(&c, 1);
        assert!(
            streams.admit(&c, std::slice::from_ref(&j), false).is_err(),
            "not resumed by an enable"
        );
        let again = streams
            .admit(&c, std::slice::from_ref(&j), true)
            .expect("restarted");
        assert_ne!(first, again);
    }

    #[test]
    fn a_batch_with_one_ended_stream_is_refused_whole() {
        let c = control();
        let (j1, j2) = (
            JointRef {
                bus: "b".into(),
                id: 1,
            },
            JointRef {
                bus: "b".into(),
                id: 2,
            },
        );
        enable(&c, 1);
        enable(&c, 2);
        let mut streams = Streams::default();
        streams
            .admit(&c, std::slice::from_ref(&j1), false)
            .expect("admitted");
        c.bus("b")
            .expect("bus")
            .authority()
            .revoke(1, Revoked::Disabled);
        assert!(streams.admit(&c, &[j2.clone(), j1.clone()], false).is_err());
        assert!(
            !streams.joints.contains_key(&j2),
            "joint 2's stream did not begin: the batch was refused whole"
        );
    }
}
