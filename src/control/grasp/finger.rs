//! One finger of a grasp, as its own task: its current limit reduced to
//! the hold current (written and verified before any finger of the job
//! moves: [`super::limit`]), then ([`run`]) position mode towards its closing
//! limit at the closing speed until the samples say contact or no contact
//! ([`super::detect`]), holding with the reduced limit, watching for
//! a lost object, until the job says release or stop, or something ends
//! it (e-stop, disable, reset, mode change, fault, offline, another
//! command taking the joint; what it watches: [`super::watch`]).
//! However it ends, the previous limit is written back and read back; a
//! task unwinding from a panic still writes it (from a spawned task) as it
//! goes.
//!
//! Every target it sends is admitted under the epoch the grasp started
//! with: once anything advances the joint's epoch, the bus owner drops
//! what the finger still sends, and the finger's next look ends it.

use std::time::{Duration, Instant};

use tokio::sync::watch;

use super::detect::{Closing, Holding, Sample, Settings, Verdict, CONTACT_SPEED_SHARE};
use super::limit::{restore, settled_in, Prepared, RestoreOnDrop};
use super::plan::{set, Finger, Plan};
use super::watch::{fresh_sample, taken_over, unfit, Watch};
use crate::bus::handle::BusEvent;
use crate::bus::{Setpoint, Source};
use crate::control::books::grasps::{Command, FingerState};
use crate::control::device::{firmware_of, measured_angle_raw};
use crate::protocol::units;

/// The longest a finger waits between looks when telemetry is quiet.
const LOOK: Duration = Duration::from_millis(20);
/// Opened: this close to the goal, degrees.
const OPEN_TOLERANCE_DEG: f64 = 1.0;
/// Opening may take its travel at the speed plus this much.
const OPEN_SLACK: Duration = Duration::from_secs(2);

/// How a finger's part ended.
enum End {
    Released,
    Stopped(String),
    Aborted(String),
}

/// Closes, holds, and ends the finger (see the module's doc); its limit
/// restored last.
pub(crate) async fn run(f: Finger, plan: Plan, prepared: Prepared, cmd: watch::Receiver<Command>) {
    let mut guard = RestoreOnDrop {
        bus: f.bus.clone(),
        id: f.id,
        prepared,
        armed: true,
    };
    let end = drive(&f, &plan, cmd).await;
    if matches!(end, End::Aborted(_)) {
        // Its target may still lie past the object: with the full limit
        // back it would squeeze with all the joint has. Held where it is
        // (dropped by the owner if an e-stop, disable or mode change
        // already took the joint).
        hold_measured(&f);
    }
    let restored = restore(&f.bus, f.id, prepared, settled_in(&f.slot)).await;
    guard.armed = false;
    set(&f.slot, |s| {
        s.current_limit_restored = restored;
        let (state, reason) = match end {
            End::Released => (FingerState::Released, None),
            End::Stopped(why) => (FingerState::Stopped, Some(why)),
            End::Aborted(why) => (FingerState::Aborted, Some(why)),
        };
        s.state = state;
        s.reason = reason;
        if !restored {
            tracing::error!(grasp_id = plan.grasp_id, bus = %s.bus, id = s.id,
                previous_a = ?s.previous_current_limit_a,
                "the joint's current limit could not be written back: it keeps the hold limit until set or power-cycled");
        }
    });
}

/// Where the finger is in its grasp.
enum Phase {
    Closing(Closing),
    Holding(Holding),
    /// No contact, or the object lost: it stays put until told.
    Waiting,
}

async fn drive(f: &Finger, plan: &Plan, mut cmd: watch::Receiver<Command>) -> End {
    let mut w = Watch::new(f);
    let dev = f.bus.snapshot().devices.get(&f.id).cloned();
    let Some(start_deg) = dev
        .as_ref()
        .and_then(measured_angle_raw)
        .map(units::angle_deg)
    else {
        return End::Aborted("the joint's angle is not known".into());
    };
    let fw = dev.as_ref().map(firmware_of).unwrap_or_default();
    if !may_send(f) {
        return End::Stopped("a move took the joint".into());
    }
    match send(f, plan.speed_dps, f.close_to_deg, fw) {
        Ok(sp) => w.sent(sp),
        Err(why) => return End::Aborted(why),
    }
    set(&f.slot, |s| s.state = FingerState::Closing);
    let started = Instant::now();
    let settings = settings_of(f, plan, start_deg);
    let mut phase = Phase::Closing(Closing::new(settings));
    // A move took the joint since (see [`may_send`]).
    let mut moved_away = false;
    loop {
        if let Err(why) = unfit(f, &mut w) {
            return End::Aborted(why);
        }
        if let Some(end) = follow_command(f, &mut w, fw, &mut cmd).await {
            return end;
        }
        let snap = w.snaps.borrow_and_update().clone();
        let dev = snap.devices.get(&f.id);
        if let Some(taken) = taken_over(dev, &mut w) {
            return End::Stopped(taken);
        }
        moved_away |= !may_send(f);
        if moved_away && dev.and_then(|d| d.target_sent) != Some(w.last_sent()) {
            return End::Stopped("a move took the joint".into());
        }
        if let Some(x) = fresh_sample(dev, &mut w, started) {
            let q = w.current;
            set(&f.slot, |s| s.q_current_a = q);
            phase = step(f, plan, phase, x, settings, &mut w);
        }
        tokio::select! {
            _ = w.snaps.changed() => {}
            _ = cmd.changed() => {}
            _ = tokio::time::sleep(LOOK) => {}
        }
    }
}

/// What the detector needs of this finger's grasp: which way it closes
/// (from where it starts), its limit, the speed and the currents.
fn settings_of(f: &Finger, plan: &Plan, start_deg: f64) -> Settings {
    Settings {
        dir: if f.close_to_deg >= start_deg {
            1.0
        } else {
            -1.0
        },
        limit_deg: f.close_to_deg,
        speed_dps: plan.speed_dps,
        threshold_a: plan.threshold_a,
        hold_a: plan.hold_a,
    }
}

/// What the job's latest command asks: `None` while it says hold; the
/// finger's end otherwise (a release opens it first). Every command but
/// Hold ends the finger's grasp: the latest one is the one that applies,
/// however many wake-ups it took to see.
async fn follow_command(
    f: &Finger,
    w: &mut Watch,
    fw: units::FirmwareVersion,
    cmd: &mut watch::Receiver<Command>,
) -> Option<End> {
    let now = cmd.borrow().clone();
    match now {
        Command::Hold => None,
        Command::Stop => Some(hold_here(f, "stopped by request")),
        Command::Release { goals, speed_dps } => {
            Some(match goals.get(f.index).copied().flatten() {
                Some(goal) => open(f, w, goal, speed_dps, fw, cmd).await,
                None => hold_here(f, "nothing to open to"),
            })
        }
    }
}

/// One sample through the phase's detector; the phase after it.
fn step(f: &Finger, plan: &Plan, phase: Phase, x: Sample, s: Settings, w: &mut Watch) -> Phase {
    match phase {
        Phase::Closing(mut c) => match c.sample(x) {
            Verdict::Closing => Phase::Closing(c),
            Verdict::Contact { deg, stalled } => {
                let joint_deg = f.cal.to_joint(deg);
                let after_ms = plan.called.elapsed().as_secs_f64() * 1e3;
                set(&f.slot, |s| {
                    s.state = FingerState::Holding;
                    s.contact = true;
                    s.contact_deg = Some(joint_deg);
                    s.contact_after_ms = Some(after_ms);
                });
                tracing::info!(grasp_id = plan.grasp_id, bus = f.bus.name(), id = f.id,
                    contact_deg = joint_deg, stalled, baseline_a = ?c.baseline(), "grasp: contact");
                f.bus.shared().emit(BusEvent::GraspContact {
                    bus: f.bus.name().to_string(),
                    grasp_id: plan.grasp_id,
                    id: f.id,
                    contact_deg: joint_deg,
                });
                set_speed(f, w, plan.speed_dps * CONTACT_SPEED_SHARE);
                Phase::Holding(Holding::new(s, x.t))
            }
            Verdict::NoContact => {
                set(&f.slot, |s| s.state = FingerState::NoContact);
                Phase::Waiting
            }
        },
        Phase::Holding(mut h) => {
            if h.brake_ends(x) {
                set_speed(f, w, plan.speed_dps);
            }
            if !h.lost(x) {
                return Phase::Holding(h);
            }
            let q = x.current_a.abs();
            set(&f.slot, |s| s.state = FingerState::Lost);
            tracing::warn!(
                grasp_id = plan.grasp_id,
                bus = f.bus.name(),
                id = f.id,
                q_current_a = q,
                "grasp: object lost"
            );
            f.bus.shared().emit(BusEvent::GraspLost {
                bus: f.bus.name().to_string(),
                grasp_id: plan.grasp_id,
                id: f.id,
                q_current_a: q,
            });
            if let Some(sp) = hold_at(f, x.deg) {
                w.sent(sp);
            }
            Phase::Waiting
        }
        Phase::Waiting => Phase::Waiting,
    }
}

/// Sends a position target at a speed limit, under the grasp's epoch.
fn send(
    f: &Finger,
    speed_dps: f64,
    deg: f64,
    fw: units::FirmwareVersion,
) -> Result<Setpoint, String> {
    let rpm = speed_dps / units::output_deg_per_s(1.0);
    let pos_ref = units::angle_to_raw(deg).map_err(|e| format!("target {deg}°: {e}"))?;
    let spd_ref = units::speed_limit_to_raw(rpm, fw).map_err(|e| format!("speed: {e}"))?;
    let sp = Setpoint { pos_ref, spd_ref };
    f.bus
        .set_targets_under(&[(f.id, sp, f.epoch)], Source::Grasp);
    Ok(sp)
}

/// False once a move took the joint since the grasp did (at its start): the finger sends
/// nothing more (a re-send would take the joint back out of the move, and
/// press on), and ends when the move's first sample is on the wire
/// ([`taken_over`]), where the joint no longer presses (the path starts
/// where it stands).
fn may_send(f: &Finger) -> bool {
    !f.bus.shared().motion.follows(f.id)
}

/// Sends the finger's target again at another speed limit (the brake
/// after contact, and its end).
fn set_speed(f: &Finger, w: &mut Watch, dps: f64) {
    if !may_send(f) {
        return;
    }
    let snap = f.bus.snapshot();
    let fw = snap.devices.get(&f.id).map(firmware_of).unwrap_or_default();
    if let Ok(spd_ref) = units::speed_limit_dps_to_raw(dps, fw) {
        let sp = Setpoint {
            pos_ref: w.last_sent().pos_ref,
            spd_ref,
        };
        f.bus
            .set_targets_under(&[(f.id, sp, f.epoch)], Source::Grasp);
        w.sent(sp);
    }
}

/// Holds the finger at `deg` (device), at its current speed limit.
fn hold_at(f: &Finger, deg: f64) -> Option<Setpoint> {
    if !may_send(f) {
        return None;
    }
    let pos_ref = units::angle_to_raw(deg).ok()?;
    let spd_ref = f
        .bus
        .snapshot()
        .devices
        .get(&f.id)
        .and_then(|d| d.target_sent)
        .map_or(0, |t| t.spd_ref);
    let sp = Setpoint { pos_ref, spd_ref };
    f.bus
        .set_targets_under(&[(f.id, sp, f.epoch)], Source::Grasp);
    Some(sp)
}

fn hold_here(f: &Finger, why: &str) -> End {
    hold_measured(f);
    End::Stopped(why.into())
}

/// Holds the finger where it was last measured.
fn hold_measured(f: &Finger) {
    let here = f
        .bus
        .snapshot()
        .devices
        .get(&f.id)
        .and_then(measured_angle_raw);
    if let Some(raw) = here {
        let _ = hold_at(f, units::angle_deg(raw));
    }
}

/// Opens to `goal` (device degrees) and waits (bounded) until it is there;
/// a stop meanwhile holds it where it is.
async fn open(
    f: &Finger,
    w: &mut Watch,
    goal: f64,
    speed_dps: f64,
    fw: units::FirmwareVersion,
    cmd: &mut watch::Receiver<Command>,
) -> End {
    if !may_send(f) {
        return End::Stopped("a move took the joint".into());
    }
    set(&f.slot, |s| s.state = FingerState::Releasing);
    match send(f, speed_dps, goal, fw) {
        Ok(sp) => w.sent(sp),
        Err(why) => return End::Aborted(why),
    }
    let here = f
        .bus
        .snapshot()
        .devices
        .get(&f.id)
        .and_then(measured_angle_raw)
        .map_or(goal, units::angle_deg);
    let travel = Duration::from_secs_f64((goal - here).abs() / speed_dps);
    let deadline = Instant::now() + travel + OPEN_SLACK;
    loop {
        if let Err(why) = unfit(f, w) {
            return End::Aborted(why);
        }
        if matches!(*cmd.borrow_and_update(), Command::Stop) {
            return hold_here(f, "stopped by request while opening");
        }
        let snap = w.snaps.borrow_and_update().clone();
        let dev = snap.devices.get(&f.id);
        if let Some(taken) = taken_over(dev, w) {
            return End::Stopped(taken);
        }
        let at = dev.and_then(measured_angle_raw).map(units::angle_deg);
        if at.is_some_and(|a| (a - goal).abs() < OPEN_TOLERANCE_DEG) {
            return End::Released;
        }
        if Instant::now() >= deadline {
            // Blocked on its way: not left aimed at a goal it presses
            // towards once its full limit is back.
            let why = format!(
                "not open within {:.1} s",
                (travel + OPEN_SLACK).as_secs_f64()
            );
            return hold_here(f, &why);
        }
        tokio::select! {
            _ = w.snaps.changed() => {}
            _ = cmd.changed() => {}
            _ = tokio::time::sleep(LOOK) => {}
        }
    }
}
