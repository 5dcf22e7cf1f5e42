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

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::BusHandle;
use crate::control::books::grasps::{FingerState, GraspView};
use crate::control::grasp::{self, GraspJoint, GraspRequest, ReleaseRequest};
use crate::control::limits::SoftLimits;
use crate::control::{Control, Options};
use crate::protocol::units;
use crate::sim::physics::HOLD_CURRENT_A;
use crate::sim::{Fault, SimHandle};

use super::args::{BenchArgs, BenchError};
use super::rig::setup_with;

const HAND: &str = "bench";
const FINGERS: [(u8, &str, f64); 3] = [(1, "f1", 10.0), (2, "f2", 15.0), (3, "f3", 20.0)];
const CLOSE_TO_DEG: f64 = 45.0;
const SPEED_DPS: f64 = 30.0;
/// A faster closing on the stiff object, reported but not judged.
const FAST_DPS: f64 = 60.0;
const HOLD_A: f64 = 0.2;
/// Soft and stiff objects, N·m per degree.
const STIFFNESS: [f64; 2] = [0.01, 0.1];
const RUNS_PER_CASE: usize = 8;
const FREE_AIR_RUNS: usize = 100;
const FREE_AIR_CLOSE_DEG: f64 = 12.0;
/// The hold is judged from this long after the last contact, over `WINDOW`.
const SETTLE: Duration = Duration::from_millis(300);
const WINDOW: Duration = Duration::from_millis(1000);
const SAMPLE: Duration = Duration::from_millis(1);
const RUN_WAIT: Duration = Duration::from_secs(15);
/// At rest after a release: this slow and this close to the target.
const REST_DEG_S: f64 = 0.5;
const REST_DEG: f64 = 0.05;
/// Goals: overshoot and steady-state error, % of the hold setting.
const MAX_OVERSHOOT_PCT: f64 = 20.0;
const MAX_HOLD_ERROR_PCT: f64 = 10.0;

/// What one case (firmware, stiffness) measured, over its runs and fingers.
#[derive(Debug, Default)]
struct Case {
    /// Call to contact, ms, per finger.
    contact_ms: [Vec<f64>; 3],
    /// Peak measured |q current| over the hold setting, %.
    measured_over_pct: Vec<f64>,
    /// Peak object push over the set force, %.
    force_over_pct: Vec<f64>,
    /// Mean measured |q current| against the setting, %.
    hold_error_pct: Vec<f64>,
    /// Mean object push against the set force, %.
    force_error_pct: Vec<f64>,
    missed: usize,
}

/// The force the hold setting makes at rest, as the q current that
/// balances the object's push: the resting current makes none.
fn set_force_a() -> f64 {
    HOLD_A - HOLD_CURRENT_A
}

/// Peaks and window sums of one grasp, per finger.
#[derive(Debug, Default, Clone, Copy)]
struct Trace {
    peak_measured: f64,
    peak_push: f64,
    measured: (f64, u32),
    push: (f64, u32),
    /// The last INFO_02 seen (each report counts once).
    last_report: Option<Instant>,
}

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
    for (k, f) in v.fingers.iter().enumerate() {
        let t = traces[k];
        match (f.state, f.contact_after_ms) {
            (FingerState::Holding, Some(ms)) => {
                case.contact_ms[k].push(ms);
                case.measured_over_pct
                    .push(((t.peak_measured - HOLD_A) / HOLD_A * 100.0).max(0.0));
                case.force_over_pct
                    .push(((t.peak_push - set_force_a()) / set_force_a() * 100.0).max(0.0));
                let mean = |(sum, n): (f64, u32)| sum / f64::from(n.max(1));
                case.hold_error_pct
                    .push((mean(t.measured) - HOLD_A).abs() / HOLD_A * 100.0);
                case.force_error_pct
                    .push((mean(t.push) - set_force_a()).abs() / set_force_a() * 100.0);
            }
            (state, _) => {
                println!(
                    "  missed: finger {} {state:?} ({}) peak measured {:.3} A, peak push {:.3} A",
                    f.joint,
                    f.reason.as_deref().unwrap_or("-"),
                    t.peak_measured,
                    t.peak_push
                );
                case.missed += 1;
            }
        }
    }
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

/// Releases grasp `id` and waits until every finger is back at rest where
/// it started (the release answers once a finger is within a degree of
/// it: the next grasp would start short of it, and each a little shorter).
async fn release(control: &Arc<Control>, sim: &SimHandle, id: u64) -> Result<(), BenchError> {
    released(control, id).await?;
    let deadline = Instant::now() + RUN_WAIT;
    loop {
        let at_rest = FINGERS.iter().all(|(fid, _, _)| {
            sim.device(*fid).is_some_and(|d| {
                d.velocity_deg_s.abs() < REST_DEG_S && (d.angle_deg - d.target_deg).abs() < REST_DEG
            })
        });
        if at_rest {
            return Ok(());
        }
        if Instant::now() > deadline {
            return Err(BenchError::Setup(format!(
                "grasp {id}: the fingers never came to rest after the release"
            )));
        }
        tokio::time::sleep(SAMPLE).await;
    }
}

async fn released(control: &Arc<Control>, id: u64) -> Result<(), BenchError> {
    let v = match grasp::release(control, id, &ReleaseRequest::default()).await {
        Ok(v) => v,
        Err(e) => {
            let view = view_of(control, id)?;
            return Err(BenchError::Setup(format!(
                "release: {e}; the grasp: {view:?}"
            )));
        }
    };
    if v.fingers.iter().any(|f| !f.current_limit_restored) {
        return Err(BenchError::Setup(format!(
            "a limit was not restored: {v:?}"
        )));
    }
    Ok(())
}

fn view_of(control: &Control, id: u64) -> Result<GraspView, BenchError> {
    grasp::get(control, id).map_err(|e| BenchError::Setup(e.to_string()))
}

/// One look at every finger: the daemon's latest INFO_02 (each report
/// once) and the simulator's object push; summed too when `in_window`.
fn sample(sim: &SimHandle, bus: &BusHandle, traces: &mut [Trace; 3], in_window: bool) {
    let snap = bus.snapshot();
    for (k, (id, _, _)) in FINGERS.iter().enumerate() {
        let t = &mut traces[k];
        let report = snap.devices.get(id).and_then(|d| d.info02.as_ref());
        if let Some((info, at)) = report.filter(|(_, at)| t.last_report != Some(*at)) {
            t.last_report = Some(*at);
            let q = units::current_a(info.q_cur).abs();
            t.peak_measured = t.peak_measured.max(q);
            if in_window {
                t.measured.0 += q;
                t.measured.1 += 1;
            }
        }
        if let Some(d) = sim.device(*id) {
            t.peak_push = t.peak_push.max(d.object_push_a);
            if in_window {
                t.push.0 += d.object_push_a;
                t.push.1 += 1;
            }
        }
    }
}

/// Prints one case; true when it met the goals (the overshoot goal on
/// both measures).
fn print_case(firmware: &str, k: f64, speed_dps: f64, c: &Case, judged: bool) -> bool {
    let stat = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let max = v.iter().copied().fold(f64::NAN, f64::max);
        (mean, max)
    };
    let contact: Vec<String> = FINGERS
        .iter()
        .zip(&c.contact_ms)
        .map(|((_, name, at), ms)| {
            let (mean, max) = stat(ms);
            format!("{name} (object at {at} deg) {mean:.0} ms (max {max:.0})")
        })
        .collect();
    let (mo_mean, mo_max) = stat(&c.measured_over_pct);
    let (fo_mean, fo_max) = stat(&c.force_over_pct);
    let (he_mean, he_max) = stat(&c.hold_error_pct);
    let (fe_mean, fe_max) = stat(&c.force_error_pct);
    let passed = c.missed == 0
        && mo_max <= MAX_OVERSHOOT_PCT
        && fo_max <= MAX_OVERSHOOT_PCT
        && he_max <= MAX_HOLD_ERROR_PCT;
    println!(
        "grasp firmware {firmware} position mode, objects {k} N*m/deg at 10/15/20 deg, {speed_dps} deg/s, \
         hold {HOLD_A} A, {} finger-grasps{}\n  \
         call->contact: {}\n  \
         overshoot, peak measured q current over the setting: mean {mo_mean:.1} % (max {mo_max:.1}); \
         peak object push over the set force ({:.2} A): mean {fo_mean:.1} % (max {fo_max:.1}) (goal <= \
         {MAX_OVERSHOOT_PCT})\n  \
         hold error, mean measured q current: mean {he_mean:.1} % (max {he_max:.1}, goal <= \
         {MAX_HOLD_ERROR_PCT}); mean push against the set force: mean {fe_mean:.1} % (max {fe_max:.1})\n  \
         missed contacts {}",
        c.measured_over_pct.len(),
        match (judged, passed) {
            (false, _) => "  (not judged)",
            (true, true) => "",
            (true, false) => "  FAILED",
        },
        contact.join(", "),
        set_force_a(),
        c.missed,
    );
    passed
}
