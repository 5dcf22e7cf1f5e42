//! `jointd bench --grasp`: grasps through the control core on the
//! simulator's objects, on both firmware revisions (position mode with the
//! reduced limit on each), at two stiffnesses: time from the call to
//! contact per finger, force overshoot (peak |q current| over the hold
//! setting), steady-state error while holding (mean |q current| against
//! the setting); then fingers closing in free air, counting false
//! contacts. The currents are the simulated joints' own (the model's, not
//! the noisy reports), sampled every millisecond.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::BusHandle;
use crate::control::grasp::{self, GraspJoint, GraspRequest, ReleaseRequest};
use crate::control::grasp_book::{FingerState, GraspView};
use crate::control::limits::SoftLimits;
use crate::control::{Control, Options};
use crate::sim::{Fault, SimHandle};

use super::{setup_with, BenchArgs, BenchError};

const HAND: &str = "bench";
const FINGERS: [(u8, &str, f64); 3] = [(1, "f1", 10.0), (2, "f2", 15.0), (3, "f3", 20.0)];
const CLOSE_TO_DEG: f64 = 45.0;
const SPEED_DPS: f64 = 30.0;
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
/// Goals: overshoot and steady-state error, % of the hold setting.
const MAX_OVERSHOOT_PCT: f64 = 20.0;
const MAX_HOLD_ERROR_PCT: f64 = 10.0;

/// What one case (firmware, stiffness) measured, over its runs and fingers.
#[derive(Debug, Default)]
struct Case {
    contact_ms: Vec<f64>,
    overshoot_pct: Vec<f64>,
    hold_error_pct: Vec<f64>,
    missed: usize,
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
            let case = rt.block_on(objects_case(&control, &sim, k))?;
            all &= print_case(firmware, k, &case);
        }
        if firmware == "2.0.1" {
            let false_contacts = rt.block_on(free_air(&control))?;
            println!(
                "grasp free air (firmware {firmware}): {FREE_AIR_RUNS} runs x {} fingers at 20..90 deg/s: \
                 {false_contacts} false contacts (goal 0)",
                FINGERS.len()
            );
            all &= false_contacts == 0;
        }
    }
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

async fn objects_case(control: &Arc<Control>, sim: &SimHandle, k: f64) -> Result<Case, BenchError> {
    for (id, _, at) in FINGERS {
        sim.inject(Fault::Object {
            dev_id: id,
            at_deg: at,
            nm_per_deg: k,
        });
    }
    let mut case = Case::default();
    for _ in 0..RUNS_PER_CASE {
        one_grasp(control, sim, &mut case).await?;
    }
    for (id, _, _) in FINGERS {
        sim.inject(Fault::RemoveObject { dev_id: id });
    }
    Ok(case)
}

/// One grasp: contact times, the peak current from the call to the end of
/// the hold window, the mean current over the window; then released.
async fn one_grasp(
    control: &Arc<Control>,
    sim: &SimHandle,
    case: &mut Case,
) -> Result<(), BenchError> {
    let view = grasp::start(control, HAND, &request(SPEED_DPS, CLOSE_TO_DEG))
        .await
        .map_err(|e| BenchError::Setup(format!("grasp: {e}")))?;
    let id = view.id;
    let mut peaks = [0.0f64; 3];
    let deadline = Instant::now() + RUN_WAIT;
    let held_at = loop {
        sample_peaks(sim, &mut peaks);
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
    let mut sums = [(0.0f64, 0u32); 3];
    while Instant::now() < window_to {
        sample_peaks(sim, &mut peaks);
        if Instant::now() >= window_from {
            for (k, (fid, _, _)) in FINGERS.iter().enumerate() {
                if let Some(d) = sim.device(*fid) {
                    sums[k].0 += d.q_current_a.abs();
                    sums[k].1 += 1;
                }
            }
        }
        tokio::time::sleep(SAMPLE).await;
    }
    let v = view_of(control, id)?;
    for (k, f) in v.fingers.iter().enumerate() {
        match (f.state, f.contact_after_ms) {
            (FingerState::Holding, Some(ms)) => {
                case.contact_ms.push(ms);
                case.overshoot_pct
                    .push(((peaks[k] - HOLD_A) / HOLD_A * 100.0).max(0.0));
                let mean = sums[k].0 / f64::from(sums[k].1.max(1));
                case.hold_error_pct
                    .push((mean - HOLD_A).abs() / HOLD_A * 100.0);
            }
            (state, _) => {
                println!(
                    "  missed: finger {} {state:?} ({}) peak {:.3} A",
                    f.joint,
                    f.reason.as_deref().unwrap_or("-"),
                    peaks[k]
                );
                case.missed += 1;
            }
        }
    }
    release(control, id).await
}

/// 100 grasps with nothing in the way, at speeds from 20 to 90 °/s: every
/// finger that says contact is a false one.
async fn free_air(control: &Arc<Control>) -> Result<usize, BenchError> {
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
        release(control, view.id).await?;
    }
    Ok(false_contacts)
}

async fn release(control: &Arc<Control>, id: u64) -> Result<(), BenchError> {
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

fn sample_peaks(sim: &SimHandle, peaks: &mut [f64; 3]) {
    for (k, (id, _, _)) in FINGERS.iter().enumerate() {
        if let Some(d) = sim.device(*id) {
            peaks[k] = peaks[k].max(d.q_current_a.abs());
        }
    }
}

/// Prints one case; true when it met the goals.
fn print_case(firmware: &str, k: f64, c: &Case) -> bool {
    let stat = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
        (mean, s.last().copied().unwrap_or(f64::NAN))
    };
    let (contact_mean, contact_max) = stat(&c.contact_ms);
    let (over_mean, over_max) = stat(&c.overshoot_pct);
    let (err_mean, err_max) = stat(&c.hold_error_pct);
    let passed = c.missed == 0 && over_max <= MAX_OVERSHOOT_PCT && err_max <= MAX_HOLD_ERROR_PCT;
    println!(
        "grasp firmware {firmware} position mode, objects {k} N*m/deg at 10/15/20 deg, {SPEED_DPS} deg/s, \
         hold {HOLD_A} A, {} finger-grasps: call->contact mean {contact_mean:.0} ms (max \
         {contact_max:.0}); overshoot mean {over_mean:.1} % (max {over_max:.1}, goal <= \
         {MAX_OVERSHOOT_PCT}); hold error mean {err_mean:.1} % (max {err_max:.1}, goal <= \
         {MAX_HOLD_ERROR_PCT}); missed contacts {}{}",
        c.contact_ms.len(),
        c.missed,
        if passed { "" } else { "  FAILED" }
    );
    passed
}
