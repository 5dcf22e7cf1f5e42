//! Turns the setpoints waiting to go out into the cheapest correct frames.
//!
//! - Two or more position-mode joints of one broadcast group (ids 1–8, 9–16)
//!   with new targets share one broadcast frame. A broadcast overwrites the
//!   target of every device of its group (SPEC §3.2), so the other slots
//!   carry each joint's current target, or its measured angle if it was never
//!   commanded, never 0. A group with a known joint that has neither, or
//!   that may hold a target the daemon does not know (found enabled at
//!   start and kept), gets no broadcast: its joints go one frame each.
//! - A broadcast carries no speed limit, so a joint whose speed limit changes
//!   gets its own control frame (which carries both).
//! - Speed-mode joints share a speed broadcast only when every known joint of
//!   the group is in speed mode (a speed broadcast would rewrite the speed
//!   limit of a position-mode joint).
//! - A single changed joint and ids above 16 get a standard control frame.
//!
//! Slots of ids with no device known on the bus carry 0: there is nothing
//! there to move (a device that powers up announces itself first).
//!
//! Pure: the owner passes the pending setpoints and a view of the devices.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::protocol::{BroadcastPos, BroadcastSpd, Command, Control, Group};

use super::setpoints::{Setpoint, StoredSetpoint};

/// What the planner needs to know about one device on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct SlotInfo {
    /// The device was put in speed mode (power-up is position mode).
    pub speed_mode: bool,
    /// The target it was last sent (position and speed limit).
    pub target: Option<Setpoint>,
    /// False while it may hold a target the daemon does not know (found
    /// enabled at start): no broadcast may overwrite it.
    pub target_known: bool,
    /// Its angle from telemetry, if fresh (not from before a re-zero).
    pub measured: Option<i16>,
    /// When a frame last carried a new target to it.
    pub last_sent: Option<Instant>,
}

/// A setpoint waiting for the wire, and since when its joint has waited
/// (a newer setpoint replacing it does not reset the wait: a joint whose
/// target keeps changing must not be starved by the others).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Pending {
    pub setpoint: StoredSetpoint,
    pub since: Instant,
}

/// One frame and the setpoints it delivers.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Planned {
    pub command: Command,
    /// Joints whose new setpoint this frame completes.
    pub carries: Vec<(u8, StoredSetpoint)>,
}

/// What to do with the pending setpoints.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Plan {
    /// Frames, the one whose joints waited longest first.
    pub frames: Vec<Planned>,
    /// Setpoints equal to what the device already has: nothing to send.
    pub settled: Vec<(u8, StoredSetpoint)>,
    /// Setpoints for ids no device answers to on this bus: dropped.
    pub unknown: Vec<u8>,
}

const SLOTS: usize = 8;

/// Plans frames for `pending`; `view(id)` is `None` for an id with no device.
pub(crate) fn plan(pending: &BTreeMap<u8, Pending>, view: impl Fn(u8) -> Option<SlotInfo>) -> Plan {
    let mut out = Plan::default();
    let mut left: BTreeMap<u8, (StoredSetpoint, SlotInfo)> = BTreeMap::new();
    for (&id, p) in pending {
        let sp = p.setpoint;
        match view(id) {
            None => out.unknown.push(id),
            Some(info) if info.target == Some(sp.setpoint) => out.settled.push((id, sp)),
            Some(info) => {
                left.insert(id, (sp, info));
            }
        }
    }
    for group in [Group::Low, Group::High] {
        let frame = position_broadcast(group, &left, &view)
            .or_else(|| speed_broadcast(group, &left, &view));
        if let Some(frame) = frame {
            for (id, _) in &frame.carries {
                left.remove(id);
            }
            out.frames.push(frame);
        }
    }
    out.frames
        .extend(left.into_iter().map(|(id, (sp, _))| Planned {
            command: Command::Control(Control::set_ref(
                id,
                sp.setpoint.pos_ref,
                sp.setpoint.spd_ref,
            )),
            carries: vec![(id, sp)],
        }));
    // Longest waiting first; on a tie (one write for every joint) the
    // joints served least recently, so two groups take turns.
    out.frames.sort_by_cached_key(|f| {
        let ids = || f.carries.iter().map(|(id, _)| *id);
        let waited = ids()
            .filter_map(|id| pending.get(&id))
            .map(|p| p.since)
            .min();
        let served = ids().map(|id| view(id).and_then(|v| v.last_sent)).min();
        (waited, served.flatten())
    });
    out
}

fn group_ids(group: Group) -> impl Iterator<Item = (usize, u8)> {
    (0..SLOTS).map(move |slot| (slot, group.first_id() + slot as u8))
}

/// A pending joint a position broadcast can complete: position mode, speed
/// limit unchanged since its last frame.
fn pos_candidate(sp: &StoredSetpoint, info: &SlotInfo) -> bool {
    !info.speed_mode && info.target.map(|t| t.spd_ref) == Some(sp.setpoint.spd_ref)
}

fn position_broadcast(
    group: Group,
    left: &BTreeMap<u8, (StoredSetpoint, SlotInfo)>,
    view: &impl Fn(u8) -> Option<SlotInfo>,
) -> Option<Planned> {
    let mut carries = Vec::new();
    let mut pos_ref = [0i16; SLOTS];
    for (slot, id) in group_ids(group) {
        pos_ref[slot] = match left.get(&id) {
            // Speed mode ignores position targets: keep where it is.
            Some((sp, info)) if info.speed_mode => info.measured.unwrap_or(sp.setpoint.pos_ref),
            Some((sp, info)) => {
                if pos_candidate(sp, info) {
                    carries.push((id, *sp));
                }
                // A joint that also needs its own frame gets its new target
                // here too, so the order of the two frames does not matter.
                sp.setpoint.pos_ref
            }
            None => match view(id) {
                None => 0,
                Some(info) if !info.target_known => return None,
                // Where it is, not 0: were it in position mode after all
                // (a reset the daemon did not see), 0 would be a target.
                Some(info) if info.speed_mode => info.measured?,
                Some(info) => info.target.map(|t| t.pos_ref).or(info.measured)?,
            },
        };
    }
    (carries.len() >= 2).then_some(Planned {
        command: Command::BroadcastPos(BroadcastPos { group, pos_ref }),
        carries,
    })
}

fn speed_broadcast(
    group: Group,
    left: &BTreeMap<u8, (StoredSetpoint, SlotInfo)>,
    view: &impl Fn(u8) -> Option<SlotInfo>,
) -> Option<Planned> {
    let mut carries = Vec::new();
    let mut spd_ref = [0i16; SLOTS];
    for (slot, id) in group_ids(group) {
        spd_ref[slot] = match (left.get(&id), view(id)) {
            (_, None) => 0,
            (_, Some(info)) if !info.speed_mode => return None,
            (Some((sp, _)), Some(_)) => {
                carries.push((id, *sp));
                sp.setpoint.spd_ref
            }
            // A speed-mode joint nobody commanded keeps its speed (0 at rest).
            (None, Some(info)) => info.target.map_or(0, |t| t.spd_ref),
        };
    }
    (carries.len() >= 2).then_some(Planned {
        command: Command::BroadcastSpd(BroadcastSpd { group, spd_ref }),
        carries,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn sp(pos: i16, spd: i16, seq: u64, t0: Instant) -> Pending {
        let accepted = t0 + Duration::from_micros(seq);
        Pending {
            setpoint: StoredSetpoint {
                setpoint: Setpoint {
                    pos_ref: pos,
                    spd_ref: spd,
                },
                seq,
                accepted,
                epoch: crate::bus::authority::Epoch(0),
            },
            since: accepted,
        }
    }

    /// Devices 1..=n in position mode, each last sent (10·id, 1000), measured 5·id.
    fn view_n(n: u8) -> impl Fn(u8) -> Option<SlotInfo> {
        move |id| {
            (1..=n).contains(&id).then_some(SlotInfo {
                speed_mode: false,
                target_known: true,
                target: Some(Setpoint {
                    pos_ref: 10 * i16::from(id),
                    spd_ref: 1000,
                }),
                measured: Some(5 * i16::from(id)),
                last_sent: None,
            })
        }
    }

    #[test]
    fn two_joints_of_a_group_share_a_broadcast_with_other_slots_filled() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([(2, sp(700, 1000, 1, t0)), (5, sp(-300, 1000, 1, t0))]);
        let p = plan(&pending, view_n(6));
        assert_eq!(p.frames.len(), 1);
        let Command::BroadcastPos(b) = p.frames[0].command else {
            panic!(
                "expected a position broadcast, got {:?}",
                p.frames[0].command
            )
        };
        assert_eq!(b.group, Group::Low);
        // Slots 1, 3, 4, 6: their current targets; 7, 8: no device there.
        assert_eq!(b.pos_ref, [10, 700, 30, 40, -300, 60, 0, 0]);
        assert_eq!(p.frames[0].carries.len(), 2);
    }

    /// Devices 1..=3; device 3 never commanded, with or without an angle.
    fn third_uncommanded(measured: Option<i16>) -> impl Fn(u8) -> Option<SlotInfo> {
        move |id| {
            (1..=3).contains(&id).then(|| SlotInfo {
                target: (id != 3).then_some(Setpoint {
                    pos_ref: 1,
                    spd_ref: 9,
                }),
                measured,
                target_known: true,
                ..SlotInfo::default()
            })
        }
    }

    #[test]
    fn never_commanded_joints_carry_their_measured_angle_never_zero() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([(1, sp(50, 9, 1, t0)), (2, sp(60, 9, 1, t0))]);
        let p = plan(&pending, third_uncommanded(Some(-1234)));
        let Command::BroadcastPos(b) = p.frames[0].command else {
            panic!("expected a broadcast")
        };
        assert_eq!(&b.pos_ref[..3], &[50, 60, -1234]);
    }

    #[test]
    fn a_slot_with_no_target_and_no_angle_forbids_the_broadcast() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([(1, sp(50, 9, 1, t0)), (2, sp(60, 9, 1, t0))]);
        let p = plan(&pending, third_uncommanded(None));
        assert_eq!(p.frames.len(), 2);
        assert!(p
            .frames
            .iter()
            .all(|f| matches!(f.command, Command::Control(_))));
    }

    #[test]
    fn a_joint_holding_an_unknown_target_forbids_the_broadcast() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([(1, sp(50, 9, 1, t0)), (2, sp(60, 9, 1, t0))]);
        let kept = |id: u8| {
            third_uncommanded(Some(-1234))(id).map(|v| SlotInfo {
                target_known: id != 3,
                ..v
            })
        };
        let p = plan(&pending, kept);
        assert_eq!(
            p.frames.len(),
            2,
            "joint 3's target must not be overwritten"
        );
        assert!(p
            .frames
            .iter()
            .all(|f| matches!(f.command, Command::Control(_))));
    }

    #[test]
    fn single_joint_high_ids_and_speed_changes_use_control_frames() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([
            (3, sp(100, 1000, 1, t0)),
            (9, sp(200, 1000, 2, t0)),
            (10, sp(300, 2000, 3, t0)),
            (20, sp(400, 1000, 4, t0)),
        ]);
        let p = plan(&pending, view_n(20));
        let ids: Vec<_> = p
            .frames
            .iter()
            .map(|f| match f.command {
                Command::Control(c) => c.dev_id,
                other => panic!("unexpected {other:?}"),
            })
            .collect();
        assert_eq!(ids, vec![3, 9, 10, 20], "oldest first");
    }

    #[test]
    fn speed_limit_change_gets_its_own_frame_and_its_new_target_in_the_broadcast() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([
            (1, sp(11, 1000, 1, t0)),
            (2, sp(22, 1000, 1, t0)),
            (3, sp(33, 5000, 1, t0)),
        ]);
        let p = plan(&pending, view_n(8));
        assert_eq!(p.frames.len(), 2);
        let bc = p
            .frames
            .iter()
            .find_map(|f| match f.command {
                Command::BroadcastPos(b) => Some(b),
                _ => None,
            })
            .expect("a broadcast");
        assert_eq!(&bc.pos_ref[..3], &[11, 22, 33]);
        assert!(p.frames.iter().any(|f| f.command
            == Command::Control(Control::set_ref(3, 33, 5000))
            && f.carries.len() == 1));
    }

    #[test]
    fn the_group_that_waited_longest_goes_first() {
        let t0 = Instant::now();
        let mut pending = BTreeMap::from([
            (1, sp(11, 1000, 5, t0)),
            (2, sp(22, 1000, 5, t0)),
            (9, sp(99, 1000, 5, t0)),
            (10, sp(101, 1000, 5, t0)),
        ]);
        // Joints 9 and 10 have waited since before 1 and 2's newest values.
        for id in [9, 10] {
            pending.get_mut(&id).unwrap().since = t0;
        }
        let p = plan(&pending, view_n(16));
        assert!(matches!(
            p.frames[0].command,
            Command::BroadcastPos(BroadcastPos {
                group: Group::High,
                ..
            })
        ));
    }

    #[test]
    fn on_a_tie_the_group_served_least_recently_goes_first() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([
            (1, sp(11, 1000, 5, t0)),
            (2, sp(22, 1000, 5, t0)),
            (9, sp(99, 1000, 5, t0)),
            (10, sp(101, 1000, 5, t0)),
        ]);
        let served = move |id: u8| {
            view_n(16)(id).map(|v| SlotInfo {
                last_sent: Some(t0 + Duration::from_micros(if id <= 8 { 2 } else { 1 })),
                ..v
            })
        };
        let p = plan(&pending, served);
        assert!(matches!(
            p.frames[0].command,
            Command::BroadcastPos(BroadcastPos {
                group: Group::High,
                ..
            })
        ));
    }

    #[test]
    fn unchanged_and_unknown_setpoints_send_nothing() {
        let t0 = Instant::now();
        let pending = BTreeMap::from([(2, sp(20, 1000, 1, t0)), (99, sp(1, 1, 1, t0))]);
        let p = plan(&pending, view_n(8));
        assert!(p.frames.is_empty());
        assert_eq!(p.settled.len(), 1);
        assert_eq!(p.unknown, vec![99]);
    }

    #[test]
    fn speed_mode_group_shares_a_speed_broadcast_only_if_all_in_speed_mode() {
        let t0 = Instant::now();
        let speed = |n: u8| {
            move |id: u8| {
                (9..=n).contains(&id).then_some(SlotInfo {
                    speed_mode: id != 12,
                    target_known: true,
                    target: None,
                    measured: Some(0),
                    last_sent: None,
                })
            }
        };
        let pending = BTreeMap::from([(9, sp(0, 500, 1, t0)), (10, sp(0, -500, 1, t0))]);
        let p = plan(&pending, speed(11));
        let Command::BroadcastSpd(b) = p.frames[0].command else {
            panic!("expected a speed broadcast")
        };
        assert_eq!(&b.spd_ref[..4], &[500, -500, 0, 0]);
        // Device 12 is in position mode: one control frame each instead.
        assert_eq!(plan(&pending, speed(12)).frames.len(), 2);
    }
}
