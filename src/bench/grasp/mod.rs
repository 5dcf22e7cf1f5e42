//! `jointd bench --grasp`: grasps through the control core on the
//! simulator's objects, on both firmware revisions (position mode with the
//! reduced limit on each), at two stiffnesses: time from the call to
//! contact per finger; force overshoot two ways, the peak q current the
//! daemon measured (the joints' noisy INFO_02 reports) over the hold
//! setting, and the peak push of the object (the true force, as the q
//! current that balances it) over the force the setting holds at rest;
//! steady-state error while holding (mean measured |q current| against the
//! setting, mean push against the set force); then fingers closing in free
//! air, counting false contacts.
//!
//! # Layout
//! - `setup`: the hand, its objects, speeds, timing and goals.
//! - `case`: one case's measurements and its printout.
//! - `calls`: a grasp's view and release through the core.
//! - this file: the cases run, one grasp, free air.

mod calls;
mod case;
mod setup;

use std::sync::Arc;
use std::time::{Duration, Instant};

use calls::{release, view_of};
use case::{print_case, sample, Case, Trace};
use setup::{
    CLOSE_TO_DEG, FAST_DPS, FINGERS, FREE_AIR_CLOSE_DEG, FREE_AIR_RUNS, HAND, HOLD_A,
    RUNS_PER_CASE, RUN_WAIT, SAMPLE, SETTLE, SPEED_DPS, STIFFNESS, WINDOW,
};

use super::args::{BenchArgs, BenchError};
use super::rig::setup_with;
use crate::bus::BusHandle;
use crate::control::books::grasps::FingerState;
use crate::control::grasp::{self, GraspJoint, GraspRequest};
use crate::control::limits::SoftLimits;
use crate::control::{Control, Options};
use crate::sim::{Fault, SimHandle};

pub(crate) fn run(args: &BenchArgs) -> Result<bool, BenchError> {
    let mut all = true;
    for firmware in ["2.0.1", "2.0.8"] {
        let ids: Vec<u8> = FINGERS.iter().map(|f| f.0).collect();
        let (sim, bus, _thread) = setup_with(args, 500_000, &ids, |cfg| {
            cfg.firmware = crate::sim::Firmware::parse(firmware).unwrap_or_default();
        })?;
        let control = control(&bus)?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()?;
        rt.block_on(daemon_sees_run(&bus, &ids))?;
        for k in STIFFNESS {
            let case = rt.block_on(objects_case(&control, &sim, &bus, k, SPEED_DPS))?;
            all &= print_case(firmware, k, SPEED_DPS, &case, true);
        }
        if firmware == "2.0.1" {
            // Outside the goals: how the overshoot grows with the speed.
            let k = STIFFNESS[STIFFNESS.len() - 1];
            let case = rt.block_on(objects_case(&control, &sim, &bus, k, FAST_DPS))?;
            print_case(firmware, k, FAST_DPS, &case, false);
            let false_contacts = rt.block_on(free_air(&control, &sim))?;
            println!(
                "grasp free air (firmware {firmware}): {FREE_AIR_RUNS} runs x {} fingers at 20..90 deg/s: \
                 {false_contacts} false contacts (goal 0)",
                FINGERS.len()
            );
            all &= false_contacts == 0;
        }
    }
    print!("{}", super::grasp_modes::report());
    Ok(all)
}

/// A control core over the bench's bus with one hand of the three fingers.
fn control(bus: &BusHandle) -> Result<Arc<Control>, BenchError> {
    let control = Arc::new(Control::new(vec![bus.clone()], SoftLimits::default()));
    let hands = crate::hands::resolve(
        &[crate::hands::HandConfig {
            name: HAND.into(),
            joints: vec![crate::hands::HandJoints {
                bus: bus.name().to_owned(),
                ids: crate::hands::Ids::List(FINGERS.iter().map(|f| f.0).collect()),
                names: FINGERS.iter().map(|f| f.1.to_owned()).collect(),
            }],
        }],
        &[bus.name().to_owned()],
    )
    .map_err(|e| BenchError::Setup(e.to_string()))?;
    let store = crate::hands::StateStore::open(hands, None)
        .map_err(|e| BenchError::Setup(e.to_string()))?;
    let options = Options {
        hands: Some(Arc::new(store)),
        ..Default::default()
    };
    control
        .set_options(options)
        .map_err(|_| BenchError::Setup("options set twice".into()))?;
    Ok(control)
}

/// Until the daemon's own view says every joint runs (a grasp starts only
/// then; the simulator says it first).
async fn daemon_sees_run(bus: &BusHandle, ids: &[u8]) -> Result<(), BenchError> {
    let mut rx = bus.watch();
    let runs = rx.wait_for(|s| {
        ids.iter().all(|id| {
            s.devices
                .get(id)
                .and_then(|d| d.info01.as_ref())
                .is_some_and(|(i, _)| i.fsm == crate::protocol::status::fsm::RUN)
        })
    });
    let seen = matches!(tokio::time::timeout(RUN_WAIT, runs).await, Ok(Ok(_)));
    if seen {
        Ok(())
    } else {
        Err(BenchError::Setup(
            "the daemon never saw every joint run".into(),
        ))
    }
}

fn request(speed_dps: f64, close_to: f64) -> GraspRequest {
    GraspRequest {
        speed_dps,
        hold_current_a: HOLD_A,
        contact_threshold_a: None,
        joints: Some(
            FINGERS
                .iter()
                .map(|f| GraspJoint {
                    joint: f.1.to_owned(),
                    close_to_deg: Some(close_to),
                })
                .collect(),
        ),
    }
}

async fn objects_case(
    control: &Arc<Control>,
    sim: &SimHandle,
    bus: &BusHandle,
    k: f64,
    speed_dps: f64,
) -> Result<Case, BenchError> {
    for (id, _, at) in FINGERS {
        sim.inject(Fault::Object {
            dev_id: id,
            at_deg: at,
            nm_per_deg: k,
        });
    }
    let mut case = Case::default();
    for _ in 0..RUNS_PER_CASE {
        one_grasp(control, sim, bus, speed_dps, &mut case).await?;
    }
    for (id, _, _) in FINGERS {
        sim.inject(Fault::RemoveObject { dev_id: id });
    }
    Ok(case)
}

/// One grasp: contact times, the peaks from the call to the end of the
/// hold window, the means over the window; then released.
async fn one_grasp(
    control: &Arc<Control>,
    sim: &SimHandle,
    bus: &BusHandle,
    speed_dps: f64,
    case: &mut Case,
) -> Result<(), BenchError> {
    let view = grasp::start(control, HAND, &request(speed_dps, CLOSE_TO_DEG))
        .await
        .map_err(|e| BenchError::Setup(format!("grasp: {e}")))?;
    let id = view.id;
    let mut traces = [Trace::default(); 3];
    let deadline = Instant::now() + RUN_WAIT;
    let held_at = loop {
        sample(sim, bus, &mut traces, false);
        let v = view_of(control, id)?;
        if v.fingers
            .iter()
            .all(|f| f.state != FingerState::Closing && f.state != FingerState::Starting)
        {
            break Instant::now();
        }
        if Instant::now() > deadline {
            return Err(BenchError::Setup(format!("grasp {id} never closed: {v:?}")));
        }
        tokio::time::sleep(SAMPLE).await;
    };
    let window_from = held_at + SETTLE;
    let window_to = window_from + WINDOW;
    while Instant::now() < window_to {
        sample(sim, bus, &mut traces, Instant::now() >= window_from);
        tokio::time::sleep(SAMPLE).await;
    }
    let v = view_of(control, id)?;
    case.tally(&v.fingers, &traces);
    release(control, sim, id).await
}

/// 100 grasps with nothing in the way, at speeds from 20 to 90 °/s: every
/// finger that says contact is a false one.
async fn free_air(control: &Arc<Control>, sim: &SimHandle) -> Result<usize, BenchError> {
    let mut false_contacts = 0;
    for run in 0..FREE_AIR_RUNS {
        let speed = 20.0 + 70.0 * (run as f64) / (FREE_AIR_RUNS as f64 - 1.0);
        let view = grasp::start(control, HAND, &request(speed, FREE_AIR_CLOSE_DEG))
            .await
            .map_err(|e| BenchError::Setup(format!("grasp: {e}")))?;
        let deadline = Instant::now() + RUN_WAIT;
        let v = loop {
            let v = view_of(control, view.id)?;
            if v.fingers
                .iter()
                .all(|f| f.state != FingerState::Closing && f.state != FingerState::Starting)
            {
                break v;
            }
            if Instant::now() > deadline {
                return Err(BenchError::Setup(format!(
                    "free-air grasp never ended: {v:?}"
                )));
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        };
        false_contacts += v.fingers.iter().filter(|f| f.contact).count();
        release(control, sim, view.id).await?;
    }
    Ok(false_contacts)
}
