//! `jointd bench --moves`: every joint doing back-to-back
//! minimum-jerk moves of 300 ms, generated and streamed by the daemon.
//! Reports the rate at which move setpoints reach the wire per joint, the
//! tracking error (the planned angle against the simulated joint's, sampled
//! every 2 ms while the moves run), occupancy and the bus thread's CPU.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::bus::motion::Follower;
use crate::bus::BusHandle;
use crate::motion::{Method, Path, RunningMove};
use crate::protocol::units;
use crate::sim::{SimHandle, SimStats};

use super::args::{BenchArgs, BenchError};
use super::rig::{cpu_now, cpu_share, setup};

/// Each move's duration and amplitude (the joints swing between ±AMPLITUDE).
const MOVE: Duration = Duration::from_millis(300);
const AMPLITUDE_DEG: f64 = 20.0;
/// How often the simulated angles are compared with the plan.
const SAMPLE_EVERY: Duration = Duration::from_millis(2);
/// Moves start this long after they are made (as the API does).
const START_DELAY: Duration = Duration::from_millis(5);
/// Occupancy the moves must still leave the wire at (500000 baud).
const MIN_OCCUPANCY: f64 = 0.95;

/// Runs the moves workload at every `--baud`; true when each met its target.
pub(crate) fn run(args: &BenchArgs) -> Result<bool, BenchError> {
    let mut all = true;
    for &baud in &args.bauds {
        let ids: Vec<u8> = (1..=args.joints).collect();
        let (sim, bus, _thread) = setup(args, baud, &ids)?;
        let warm_until = Instant::now() + Duration::from_secs_f64(args.warmup);
        let mut swing = Swing::new(&ids);
        while Instant::now() < warm_until {
            swing.one_move(&bus, &sim, None)?;
        }
        let (s0, cpu0) = (sim.stats(), cpu_now());
        let sent0 = bus.snapshot().counters.setpoints_sent;
        let until = Instant::now() + Duration::from_secs_f64(args.seconds);
        let mut errors: Vec<f64> = Vec::new();
        let mut moves = 0u32;
        while Instant::now() < until {
            swing.one_move(&bus, &sim, Some(&mut errors))?;
            moves += 1;
        }
        let (s1, cpu1) = (sim.stats(), cpu_now());
        let sent = bus.snapshot().counters.setpoints_sent - sent0;
        let report = Report::new(baud, &ids, moves, sent, &errors, &s0, &s1, &cpu0, &cpu1);
        println!("{report}");
        all &= report.passed;
    }
    Ok(all)
}

/// The joints swinging between ±AMPLITUDE, even and odd ids in opposition.
struct Swing {
    ids: Vec<u8>,
    next_id: u64,
    toward_plus: bool,
}

impl Swing {
    fn new(ids: &[u8]) -> Self {
        Self {
            ids: ids.to_vec(),
            next_id: 0,
            toward_plus: true,
        }
    }

    fn target(&self, id: u8) -> f64 {
        let sign = if (id % 2 == 0) == self.toward_plus {
            1.0
        } else {
            -1.0
        };
        sign * AMPLITUDE_DEG
    }

    /// One move of every joint from where it was sent last to the next
    /// swing target; with `errors`, the tracking error sampled while it runs.
    fn one_move(
        &mut self,
        bus: &BusHandle,
        sim: &SimHandle,
        errors: Option<&mut Vec<f64>>,
    ) -> Result<(), BenchError> {
        let snap = bus.snapshot();
        let start: Vec<f64> = self
            .ids
            .iter()
            .map(|id| {
                snap.devices
                    .get(id)
                    .and_then(|d| d.target_sent)
                    .map_or(0.0, |t| units::angle_deg(t.pos_ref))
            })
            .collect();
        let target: Vec<f64> = self.ids.iter().map(|id| self.target(*id)).collect();
        self.toward_plus = !self.toward_plus;
        let path = Path::to(Method::MinJerk, start, target, MOVE)
            .map_err(|e| BenchError::Setup(e.to_string()))?;
        // Ample speed limit: the bench measures the path, not the limit.
        let spd_ref = units::speed_limit_to_raw(20_000.0, Default::default())
            .map_err(|e| BenchError::Setup(e.to_string()))?;
        self.next_id += 1;
        let mv = Arc::new(RunningMove::new(
            self.next_id,
            path,
            Instant::now() + START_DELAY,
        ));
        let followers = self
            .ids
            .iter()
            .enumerate()
            // Under each joint's current epoch, as the control core admits a move.
            .map(|(joint, id)| Follower::new(*id, mv.clone(), joint, spd_ref, bus.grant(*id).epoch))
            .collect();
        bus.follow(followers);
        let end = mv.start() + MOVE;
        let mut errors = errors;
        while Instant::now() < end {
            std::thread::sleep(SAMPLE_EVERY);
            if let Some(errors) = errors.as_deref_mut() {
                let t = mv.elapsed_at(Instant::now());
                for (joint, id) in self.ids.iter().enumerate() {
                    if let Some(d) = sim.device(*id) {
                        errors.push(d.angle_deg - mv.path.sample(joint, t).position);
                    }
                }
            }
        }
        Ok(())
    }
}

struct Report {
    text: String,
    passed: bool,
}

impl Report {
    #[allow(clippy::too_many_arguments)]
    fn new(
        baud: u32,
        ids: &[u8],
        moves: u32,
        setpoints_sent: u64,
        errors: &[f64],
        s0: &SimStats,
        s1: &SimStats,
        cpu0: &[Duration],
        cpu1: &[Duration],
    ) -> Self {
        let wall = s1.at.saturating_duration_since(s0.at).as_secs_f64();
        let occupancy = SimStats::occupancy(s0, s1);
        let per_joint = setpoints_sent as f64 / wall.max(f64::EPSILON) / ids.len().max(1) as f64;
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        let max = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        let cpu = cpu_share(cpu0, cpu1, s0, s1, 0);
        let min_occupancy = if baud >= 500_000 { MIN_OCCUPANCY } else { 0.0 };
        let checks = [
            (
                format!("occupancy >= {MIN_OCCUPANCY} (at 500000 baud)"),
                occupancy >= min_occupancy,
            ),
            (
                "zero collisions".to_string(),
                s1.collisions == s0.collisions,
            ),
        ];
        let mut text = format!(
            "== moves: {} joints at {baud} baud, back-to-back min-jerk moves of {} ms between ±{AMPLITUDE_DEG}°, {moves} moves in {wall:.1} s\n\
             \x20 move setpoints on the wire per joint  {per_joint:.1}/s\n\
             \x20 tracking error (simulated - planned) RMS {rms:.2}°, max {max:.2}° ({} samples)\n\
             \x20 wire occupancy (simulator referee)  {occupancy:.4}\n\
             \x20 collisions                          {}\n\
             \x20 daemon CPU (bus owner thread)       {:.1} % of one core\n",
            ids.len(),
            MOVE.as_millis(),
            errors.len(),
            s1.collisions - s0.collisions,
            cpu * 100.0,
        );
        for (what, ok) in &checks {
            text.push_str(&format!("  [{}] {what}\n", if *ok { "ok" } else { "FAIL" }));
        }
        Self {
            text,
            passed: checks.iter().all(|(_, ok)| *ok),
        }
    }
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}
