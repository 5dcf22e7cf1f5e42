//! The randomized safety test: many random interleavings of enable, disable,
//! e-stop, mode change, target, a WebSocket setpoint stream ending in its
//! watchdog, move, pose go, homing, grasp (started over REST or the
//! WebSocket, closing on a simulated object or on nothing, released,
//! stopped or left holding), a simulated power cycle
//! and e-stop races, on the
//! simulator through the daemon's own API. After every step the invariant
//! is checked on the simulated devices themselves:
//!
//! > a joint moves only toward what the last command admitted since its last
//! > enable asked.
//!
//! And a second, on each joint's measured angle:
//!
//! > a joint under a move, pose, grasp or release stays between where it
//! > stood when the command was admitted and the command's goal (±2°;
//! > a joint moving then also as far as it carries on in 50 ms, since a
//! > path starts at rest).
//!
//! Steps for it besides: a slow target and then a move the other way, a
//! grasp taken over by a move, and a bus unplugged while a grasp holds
//! (the limits must be written back once it is plugged in again).
//!
//! Per joint the test keeps what was admitted since its last enable (where
//! it stood when enabled, each accepted target, the span of each accepted
//! move or pose, the speeds of accepted speed targets). An enabled device's
//! position target must lie within one of those, and in speed mode its speed
//! reference must be 0 or an admitted speed. A step is checked once the bus
//! owner has made frames since it (its poll counter moved on), so what was
//! pending has reached the wire.
//!
//! Seeds: `JOINTD_SAFETY_SEEDS` (count, default 5) and `JOINTD_SAFETY_STEPS`
//! (per seed, default 60), or one `JOINTD_SAFETY_SEED` to replay; a failure
//! prints its seed and the steps that led to it (`JOINTD_SAFETY_LOG` prints
//! them for a run that passes too; `JOINTD_SAFETY_TRACE` each joint after each step).

mod support;

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use jointd::protocol::status::fsm;
use jointd::protocol::CtrlMode;
use jointd::sim::Fault;
use serde_json::{json, Value};
use support::sim_bus::{start, SimBus, WAIT};
use tokio_tungstenite::tungstenite::Message;

const JOINTS: [u8; 3] = [1, 2, 3];
/// Slack on an angle: measurement and the device's own rounding (Q7).
const SLACK_DEG: f64 = 1.0;
/// Slack on the measured angle under a generated path: the sample the
/// daemon started from may be a telemetry period old.
const PATH_SLACK_DEG: f64 = 2.0;
/// How long a joint moving when a path starts carries on its way (see
/// [`World::under_path`]): the sample's age and the braking, seconds.
const BRAKE_S: f64 = 0.05;

/// A generated path a joint is under: the span from where it stood when
/// the command was admitted to the command's goal.
#[derive(Debug, Clone)]
struct Under {
    lo: f64,
    hi: f64,
    what: String,
}

impl Under {
    fn new(points: &[f64], what: String) -> Self {
        let lo = points.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = points.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Self { lo, hi, what }
    }
}

/// A small deterministic generator (xorshift64*): a seed replays a run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn joint(&mut self) -> u8 {
        JOINTS[self.below(JOINTS.len() as u64) as usize]
    }
    fn angle(&mut self) -> f64 {
        // Joint 2 has soft limits of ±45° in the fixture.
        (self.below(81) as f64) - 40.0
    }
}

/// What was admitted for one joint since its last enable.
#[derive(Debug, Default, Clone)]
struct Admitted {
    /// Position spans (a point is a span of width 0).
    spans: Vec<(f64, f64)>,
    /// Speed references admitted since the last enable or mode change, rpm.
    speeds: Vec<f64>,
}

impl Admitted {
    fn span(&mut self, a: f64, b: f64) {
        self.spans.push((a.min(b), a.max(b)));
    }
    fn allows_position(&self, deg: f64) -> bool {
        self.spans
            .iter()
            .any(|(lo, hi)| deg >= lo - SLACK_DEG && deg <= hi + SLACK_DEG)
    }
    /// `raw` is the device's Q15 speed reference; its base speed depends on
    /// the firmware (50000 rpm, or 40000 before 1.2.4): either may apply.
    fn allows_speed(&self, raw: i16) -> bool {
        raw == 0
            || [50_000.0, 40_000.0].iter().any(|base| {
                let rpm = f64::from(raw) / 32767.0 * base;
                self.speeds
                    .iter()
                    .any(|s| (s - rpm).abs() <= 0.02 * s.abs() + 1.0)
            })
    }
}

struct World {
    b: SimBus,
    rng: Rng,
    seed: u64,
    log: Vec<String>,
    admitted: [Admitted; 4],
    /// The generated path each joint is under, if any.
    under: [Option<Under>; 4],
    /// The bus went away and came back since the joint's last enable: the
    /// daemon may hold it where it stands when it finds it again.
    after_outage: [bool; 4],
}

impl World {
    fn device(&self, id: u8) -> jointd::sim::DeviceView {
        self.b.sim.device(id).expect("simulated device")
    }

    fn fail(&self, what: String) -> ! {
        panic!(
            "seed {} (replay: JOINTD_SAFETY_SEED={}): {what}\nsteps:\n  {}",
            self.seed,
            self.seed,
            self.log.join("\n  ")
        );
    }

    /// The owner has polled `n` more times: every setpoint pending when
    /// this was called has been made into a frame or dropped.
    async fn fence(&self) {
        let start = self.b.handle.snapshot().counters.polls;
        self.b
            .wait_snapshot("the owner polling on", |s| s.counters.polls >= start + 8)
            .await;
    }

    /// The device as the simulator and the daemon see it, for a failure.
    fn both_views(&self, id: u8) -> String {
        let d = self.device(id);
        let snap = self.b.handle.snapshot();
        let ours = snap.devices.get(&id);
        format!(
            "simulator: fsm {} mode {} aligned {} angle {:.2}° target {:.2}°; daemon: mode {:?} target {:?} reason {:?} resets {}",
            d.fsm,
            d.mode,
            d.aligned,
            d.angle_deg,
            d.target_deg,
            ours.and_then(|s| s.mode),
            ours.and_then(|s| s.target_sent),
            ours.and_then(|s| s.disabled_reason),
            ours.map_or(0, |s| s.resets),
        )
    }

    fn check(&self) {
        for id in JOINTS {
            let d = self.device(id);
            if !d.enabled {
                continue;
            }
            let a = &self.admitted[usize::from(id)];
            if d.mode == CtrlMode::Speed {
                if !a.allows_speed(d.spd_ref) {
                    self.fail(format!(
                        "joint {id} spins with a speed reference of {} (Q15); admitted since its enable (rpm): {:?}; {}",
                        d.spd_ref, a.speeds, self.both_views(id)
                    ));
                }
            } else if !a.allows_position(d.target_deg) && !self.holds_after_outage(id, &d) {
                self.fail(format!(
                    "joint {id} holds a target of {:.2}° that nothing admitted since its enable asked; admitted: {:?}; {}",
                    d.target_deg, a.spans, self.both_views(id)
                ));
            }
            if let Some(u) = &self.under[usize::from(id)] {
                if d.angle_deg < u.lo - PATH_SLACK_DEG || d.angle_deg > u.hi + PATH_SLACK_DEG {
                    self.fail(format!(
                        "joint {id} is at {:.2}°, outside {:.2}..{:.2}° (where it stood when {} was admitted, and its goal); {}",
                        d.angle_deg, u.lo, u.hi, u.what, self.both_views(id)
                    ));
                }
            }
        }
    }

    /// `PUT` joint `id`'s target.
    async fn put_target(&self, id: u8, body: &Value) -> support::http::Resp {
        self.b
            .server
            .put(
                &format!("/api/v1/buses/sim0/devices/{id}/target"),
                body.clone(),
            )
            .await
    }

    /// Joint `id` in position mode and enabled, as a user readies it.
    async fn ready(&mut self, id: u8) {
        let d = self.device(id);
        if d.mode == CtrlMode::Speed {
            self.mode(id, false).await;
        }
        if !self.device(id).enabled || !self.b.handle.grant(id).enabled {
            self.enable(id).await;
        }
    }

    /// Held where it stands by a bus that came back (see [`World::after_outage`]).
    fn holds_after_outage(&self, id: u8, d: &jointd::sim::DeviceView) -> bool {
        self.after_outage[usize::from(id)] && (d.target_deg - d.angle_deg).abs() <= SLACK_DEG
    }

    /// Joint `id` is under no generated path any more (another command
    /// took it, or it stopped).
    fn not_under(&mut self, id: u8) {
        self.under[usize::from(id)] = None;
    }

    /// Joint `id` is under a path from `stood` (where it was when the
    /// command was asked, and when it was answered) to `goal`.
    /// A joint moving when the command came carries on its way a little
    /// while it brakes: a path starts at rest where the joint was measured
    /// (a telemetry sample up to a period old), so the span takes in what
    /// the joint covers in [`BRAKE_S`] at the speed it had then.
    fn under_path(&mut self, id: u8, stood: (f64, f64), goal: f64, what: String) {
        let v = self.device(id).velocity_deg_s;
        let carried = stood.1 + v * BRAKE_S;
        self.under[usize::from(id)] = Some(Under::new(&[stood.0, stood.1, carried, goal], what));
    }

    async fn enable(&mut self, id: u8) {
        let before = self.device(id);
        let r = self
            .b
            .server
            .post(
                &format!("/api/v1/buses/sim0/devices/{id}/enable"),
                json!({}),
            )
            .await;
        self.log.push(format!("enable {id}: {}", r.status));
        self.not_under(id);
        self.after_outage[usize::from(id)] = false;
        if r.status.is_success() {
            self.b.wait_fsm(id, fsm::RUN).await;
        }
        // An enable whose confirmation was lost (504 on a loaded host) may
        // still have reached the joint: the device says.
        if self.device(id).enabled {
            // Enabled (from rest, or again while it ran): it holds where it
            // stood (it may have coasted, or been on its way), and nothing
            // admitted before applies.
            let after = self.device(id);
            let mut a = Admitted::default();
            a.span(before.angle_deg, after.angle_deg);
            self.admitted[usize::from(id)] = a;
        }
    }

    async fn disable(&mut self, id: u8) {
        let r = self
            .b
            .server
            .post(
                &format!("/api/v1/buses/sim0/devices/{id}/disable"),
                json!({}),
            )
            .await;
        self.log.push(format!("disable {id}: {}", r.status));
        self.not_under(id);
    }

    async fn estop(&mut self) {
        let r = self.b.server.post_empty("/api/v1/estop").await;
        self.log.push(format!("estop: {}", r.status));
        self.under = Default::default();
    }

    async fn mode(&mut self, id: u8, speed: bool) {
        let before = self.device(id);
        let mode = if speed { "speed" } else { "position" };
        let r = self
            .b
            .server
            .put(
                &format!("/api/v1/buses/sim0/devices/{id}/mode"),
                json!({ "mode": mode }),
            )
            .await;
        self.log.push(format!("mode {id} {mode}: {}", r.status));
        self.not_under(id);
        if r.status.is_success() {
            let after = self.device(id);
            let a = &mut self.admitted[usize::from(id)];
            a.speeds.clear();
            // Into position mode the device holds where it is.
            a.span(before.angle_deg, after.angle_deg);
        }
    }

    async fn target(&mut self, id: u8) {
        let speed = self.device(id).mode == CtrlMode::Speed;
        let body = if speed {
            json!({"speed_dps": (self.rng.below(160) as f64) - 80.0})
        } else {
            json!({"position_deg": self.rng.angle()})
        };
        let r = self.put_target(id, &body).await;
        self.log.push(format!("target {id} {body}: {}", r.status));
        if r.status.is_success() {
            self.not_under(id);
            let a = &mut self.admitted[usize::from(id)];
            match (body["speed_dps"].as_f64(), body["position_deg"].as_f64()) {
                (Some(dps), _) => a.speeds.push(jointd::protocol::units::rotor_rpm(dps)),
                (_, Some(deg)) => a.span(deg, deg),
                _ => {}
            }
        }
    }

    /// A move of one or two joints; each admitted joint's span is where its
    /// device target was to where it goes.
    async fn move_joints(&mut self, ids: &[u8], ms: u64) {
        let goals: Vec<(u8, f64)> = ids.iter().map(|&id| (id, self.rng.angle())).collect();
        // A path starts where the joint was last sent, or where it is.
        let from: Vec<(f64, f64)> = ids
            .iter()
            .map(|&id| {
                let d = self.device(id);
                (d.target_deg, d.angle_deg)
            })
            .collect();
        let joints: Vec<Value> = goals
            .iter()
            .map(|(id, deg)| json!({"bus": "sim0", "id": id, "position_deg": deg}))
            .collect();
        let r = self
            .b
            .server
            .post(
                "/api/v1/moves",
                json!({"joints": joints, "duration_ms": ms, "method": "min_jerk"}),
            )
            .await;
        self.log
            .push(format!("move {goals:?} in {ms} ms: {}", r.status));
        if r.status.as_u16() == 201 {
            for ((id, deg), (target, angle)) in goals.iter().zip(from) {
                let a = &mut self.admitted[usize::from(*id)];
                a.span(target.min(angle), *deg);
                a.span(target.max(angle), *deg);
                let now = self.device(*id).angle_deg;
                self.under_path(*id, (angle, now), *deg, format!("move to {deg:.1}°"));
            }
        }
    }

    async fn pose_go(&mut self) {
        let positions: Vec<f64> = (0..2).map(|_| self.rng.angle()).collect();
        let r = self
            .b
            .server
            .put(
                "/api/v1/hands/h/poses/p",
                json!({ "positions_deg": {"a": positions[0], "b": positions[1]} }),
            )
            .await;
        assert!(r.status.is_success(), "saving the pose: {}", r.body);
        let from: Vec<(f64, f64)> = [1u8, 2]
            .iter()
            .map(|&id| {
                let d = self.device(id);
                (d.target_deg, d.angle_deg)
            })
            .collect();
        let r = self
            .b
            .server
            .post(
                "/api/v1/hands/h/poses/p/go",
                json!({"duration_ms": 1500, "method": "min_jerk"}),
            )
            .await;
        self.log
            .push(format!("pose go {positions:?}: {}", r.status));
        if r.status.as_u16() == 201 {
            for (k, id) in [1u8, 2].into_iter().enumerate() {
                let (target, angle) = from[k];
                let a = &mut self.admitted[usize::from(id)];
                a.span(target.min(angle), positions[k]);
                a.span(target.max(angle), positions[k]);
                let now = self.device(id).angle_deg;
                let goal = positions[k];
                self.under_path(id, (angle, now), goal, format!("pose go to {goal:.1}°"));
            }
        }
    }

    /// A WebSocket client streams a few setpoints under a watchdog, then
    /// goes silent until the watchdog fires (hold or disable). On a loaded
    /// host the watchdog may fire between two setpoints too.
    async fn stream(&mut self, id: u8) {
        let url = format!(
            "{}/api/v1/ws",
            self.b.server.base.replace("http://", "ws://")
        );
        let (mut ws, _) = tokio_tungstenite::connect_async(url)
            .await
            .expect("ws connect");
        let disable = self.rng.below(2) == 0;
        let policy = if disable { "disable" } else { "hold" };
        let before = self.device(id);
        let mut hull = vec![before.angle_deg, before.target_deg];
        let arm = json!({"type": "watchdog", "seq": 1, "hold_timeout_ms": 40, "policy": policy});
        ws.send(Message::text(arm.to_string())).await.expect("send");
        let mut accepted = 0;
        let mut fired_since_ack = false;
        for seq in 2..6u64 {
            let deg = self.rng.angle();
            let msg = json!({"type": "setpoints", "seq": seq, "ack": true,
                "targets": [{"bus": "sim0", "id": id, "position_deg": deg}]});
            ws.send(Message::text(msg.to_string())).await.expect("send");
            let (reply, fired) = reply_to(&mut ws, seq).await;
            fired_since_ack |= fired;
            match reply.as_deref() {
                Some("ack") => {
                    self.under[usize::from(id)] = None;
                    accepted += 1;
                    fired_since_ack = false;
                    hull.push(deg);
                    self.admitted[usize::from(id)].span(deg, deg);
                }
                _ => break,
            }
        }
        self.log
            .push(format!("stream to {id} ({policy}): {accepted} accepted"));
        if accepted == 0 {
            return;
        }
        if !fired_since_ack {
            let fired = tokio::time::timeout(WAIT, async {
                while let Some(Ok(m)) = ws.next().await {
                    if is_watchdog(&m) {
                        return;
                    }
                }
            })
            .await;
            assert!(fired.is_ok(), "the watchdog never fired");
        }
        if !disable {
            // Held where it was measured when the watchdog fired: on its way
            // from where it stood through the streamed targets.
            let lo = hull.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = hull.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            self.admitted[usize::from(id)].span(lo, hi);
        }
        self.log.push(format!("watchdog fired ({policy})"));
    }

    /// Homing on a joint with no hard stop: it turns in speed mode until
    /// its travel bound, then holds (in position mode) where it ended.
    async fn homing(&mut self, id: u8) {
        let d = self.device(id);
        let (speed_dps, travel) = (30.0, 8.0);
        let r = self
            .b
            .server
            .post(
                "/api/v1/homing",
                json!({"joints": [{"bus": "sim0", "id": id}], "speed_dps": speed_dps,
                       "max_travel_deg": travel, "timeout_ms": 3000}),
            )
            .await;
        self.log.push(format!("homing {id}: {}", r.status));
        if r.status.is_success() {
            self.not_under(id);
            let rpm = speed_dps / jointd::protocol::units::output_deg_per_s(1.0);
            let a = &mut self.admitted[usize::from(id)];
            a.speeds.extend([rpm, -rpm]);
            let reach = travel + 2.0;
            a.span(
                d.angle_deg.min(d.target_deg) - reach,
                d.angle_deg.max(d.target_deg) + reach,
            );
        }
    }

    /// A grasp of hand `h` (joints 1 and 2) towards random closing limits,
    /// sometimes on an object placed on joint 1's way; then released (back
    /// to where the fingers started), stopped, or left to whatever follows.
    async fn grasp(&mut self) {
        if let Some((id, _)) = self.start_grasp().await {
            match self.rng.below(3) {
                0 => {
                    self.b
                        .server
                        .post(&format!("/api/v1/grasps/{id}/release"), json!({}))
                        .await;
                    self.log.push(format!("grasp {id} released"));
                }
                1 => {
                    self.b
                        .server
                        .post_empty(&format!("/api/v1/grasps/{id}/stop"))
                        .await;
                    self.log.push(format!("grasp {id} stopped"));
                }
                _ => {}
            }
        }
        self.b.sim.inject(Fault::RemoveObject { dev_id: 1 });
    }

    /// Starts a grasp of hand `h` (joints 1 and 2) over REST or the
    /// WebSocket, each finger closing (towards higher angles) to a random
    /// limit, sometimes on an object placed on joint 1's way; its id.
    async fn start_grasp(&mut self) -> Option<(u64, f64)> {
        // Mostly on a hand ready for it (as a user would make it), so the
        // steps after it have a grasp to act on.
        if self.rng.below(4) != 0 {
            for joint in [1u8, 2] {
                self.ready(joint).await;
            }
        }
        let from: Vec<(f64, f64)> = [1u8, 2]
            .iter()
            .map(|&id| {
                let d = self.device(id);
                (d.target_deg, d.angle_deg)
            })
            .collect();
        // Joint 2's soft limits are ±45°.
        let close_to: Vec<f64> = from
            .iter()
            .map(|(_, angle)| (angle + 5.0 + self.rng.below(35) as f64).min(44.0))
            .collect();
        if self.rng.below(2) == 0 {
            let at = (from[0].1 + close_to[0]) / 2.0;
            self.b.sim.inject(Fault::Object {
                dev_id: 1,
                at_deg: at,
                nm_per_deg: 0.05,
            });
        }
        let body = json!({"speed_dps": 60.0, "hold_current_a": 0.2, "joints": [
            {"joint": "a", "close_to_deg": close_to[0]},
            {"joint": "b", "close_to_deg": close_to[1]}]});
        let started = if self.rng.below(2) == 0 {
            self.grasp_over_ws(body, close_to.clone()).await
        } else {
            let r = self.b.server.post("/api/v1/hands/h/grasp", body).await;
            self.log.push(format!("grasp {close_to:?}: {}", r.status));
            (r.status.as_u16() == 202).then(|| r.body["id"].as_u64().expect("a grasp id"))
        };
        let id = started?;
        for (k, joint) in [1u8, 2].into_iter().enumerate() {
            let (target, angle) = from[k];
            let a = &mut self.admitted[usize::from(joint)];
            a.span(target.min(angle), close_to[k]);
            a.span(target.max(angle), close_to[k]);
            let now = self.device(joint).angle_deg;
            let what = format!("grasp {id} (closing to {:.1}°, or released)", close_to[k]);
            self.under_path(joint, (angle, now), close_to[k], what);
        }
        Some((id, close_to[0]))
    }

    /// A finger that ended before it closed (its limit could not be set:
    /// the bus went away) never took its joint: what came before applies.
    fn unless_closing(&mut self, view: &Value) {
        for f in view["fingers"].as_array().into_iter().flatten() {
            if f["state"] == "failed" {
                if let Some(j) = f["id"].as_u64().and_then(|j| u8::try_from(j).ok()) {
                    self.not_under(j);
                }
            }
        }
    }

    /// Until joint 1 (finger `a` of grasp `id`) has the grasp's target
    /// `close_to` on the device, or the grasp's view says the finger is
    /// past closing (holding, or ended).
    async fn grasp_under_way(&self, id: u64, close_to: f64) {
        let path = format!("/api/v1/grasps/{id}");
        let deadline = tokio::time::Instant::now() + WAIT;
        loop {
            if (self.device(1).target_deg - close_to).abs() < 0.5 {
                return;
            }
            let v = self.b.server.get(&path).await.body;
            let state = v["fingers"]
                .as_array()
                .and_then(|f| f.iter().find(|f| f["joint"] == "a"))
                .map_or("?".to_string(), |f| {
                    f["state"].as_str().unwrap_or("?").to_string()
                });
            if v["state"] == "done" || !(state == "starting" || state == "closing") {
                return;
            }
            if tokio::time::Instant::now() >= deadline {
                self.fail(format!("grasp {id} never under way: {v}"));
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }

    /// A grasp, then a move that takes one finger out of it while it
    /// closes or holds: the finger goes from where it stands, never on
    /// into the object.
    async fn grasp_taken_over_by_a_move(&mut self) {
        if let Some((id, close_to)) = self.start_grasp().await {
            self.grasp_under_way(id, close_to).await;
            let ms = 300 + self.rng.below(1200);
            self.move_joints(&[1], ms).await;
        }
        self.b.sim.inject(Fault::RemoveObject { dev_id: 1 });
    }

    /// A slow target, and while the joint is on its way a move the other
    /// way: the move starts where the joint is, not from the target.
    async fn slow_target_then_move(&mut self, id: u8) {
        self.ready(id).await;
        if self.device(id).mode == CtrlMode::Speed {
            return self.target(id).await;
        }
        let here = self.device(id).angle_deg;
        let far = if here < 0.0 { 40.0 } else { -40.0 };
        let body = json!({"position_deg": far, "speed_dps": 10});
        let r = self.put_target(id, &body).await;
        self.log
            .push(format!("slow target {id} {body}: {}", r.status));
        if !r.status.is_success() {
            return;
        }
        self.not_under(id);
        self.admitted[usize::from(id)].span(far, far);
        // On its way (a degree or so), or stopped by something else.
        let deadline = tokio::time::Instant::now() + Duration::from_secs(1);
        while (self.device(id).angle_deg - here).abs() < 1.0
            && self.device(id).enabled
            && tokio::time::Instant::now() < deadline
        {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        let back = -far / 4.0;
        let stood = self.device(id).angle_deg;
        let joints = json!([{"bus": "sim0", "id": id, "position_deg": back}]);
        let r = self
            .b
            .server
            .post(
                "/api/v1/moves",
                json!({"joints": joints, "duration_ms": 800}),
            )
            .await;
        self.log.push(format!(
            "move {id} back to {back} from {stood:.1}: {}",
            r.status
        ));
        if r.status.as_u16() == 201 {
            self.admitted[usize::from(id)].span(stood, back);
            let now = self.device(id).angle_deg;
            self.under_path(id, (stood, now), back, format!("move back to {back:.1}°"));
        }
    }

    /// The bus unplugged for a moment while a grasp closes or holds: every
    /// finger ends, and once the bus is back each lowered limit is written
    /// and read back (owed until then), before anything else moves them.
    async fn grasp_unplugged(&mut self) {
        let Some((id, close_to)) = self.start_grasp().await else {
            return;
        };
        self.grasp_under_way(id, close_to).await;
        let before: Vec<f64> = JOINTS.iter().map(|&j| self.device(j).angle_deg).collect();
        self.b.sim.inject(Fault::Unplug);
        self.b
            .wait_snapshot("the bus down", |s| {
                matches!(s.link, jointd::bus::handle::LinkState::Down { .. })
            })
            .await;
        self.b.sim.inject(Fault::Replug);
        self.b
            .wait_snapshot("the bus up", |s| {
                s.link == jointd::bus::handle::LinkState::Up
            })
            .await;
        self.log.push(format!("grasp {id}: bus unplugged and back"));
        // A bus that comes back may hold a joint where it stands: anywhere
        // it went while the bus was away, or where it is when found again.
        for (k, &j) in JOINTS.iter().enumerate() {
            let now = self.device(j).angle_deg;
            self.admitted[usize::from(j)].span(before[k], now);
            self.after_outage[usize::from(j)] = true;
        }
        let deadline = tokio::time::Instant::now() + WAIT * 2;
        loop {
            let v = self
                .b
                .server
                .get(&format!("/api/v1/grasps/{id}"))
                .await
                .body;
            let back = v["state"] == "done"
                && v["fingers"]
                    .as_array()
                    .is_some_and(|f| f.iter().all(|f| f["current_limit_restored"] == true))
                && [1u8, 2]
                    .iter()
                    .all(|j| self.b.handle.owed_limits().get(*j).is_none());
            if back {
                self.unless_closing(&v);
                break;
            }
            if tokio::time::Instant::now() >= deadline {
                self.fail(format!(
                    "grasp {id}: a limit never came back after the unplug: {v}"
                ));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        self.b.sim.inject(Fault::RemoveObject { dev_id: 1 });
    }

    /// The same grasp started over the WebSocket (`grasp`, answered
    /// `grasp_started` or `error`); the connection closes, the grasp goes on.
    async fn grasp_over_ws(&mut self, mut body: Value, close_to: Vec<f64>) -> Option<u64> {
        let url = format!(
            "{}/api/v1/ws",
            self.b.server.base.replace("http://", "ws://")
        );
        let (mut ws, _) = tokio_tungstenite::connect_async(url)
            .await
            .expect("ws connect");
        body["type"] = json!("grasp");
        body["seq"] = json!(1);
        body["hand"] = json!("h");
        ws.send(Message::text(body.to_string()))
            .await
            .expect("send");
        let answer = tokio::time::timeout(WAIT, async {
            while let Some(Ok(m)) = ws.next().await {
                if let Message::Text(t) = m {
                    let v: Value = serde_json::from_str(t.as_str()).ok()?;
                    if v["ref_seq"] == 1 {
                        return Some(v);
                    }
                }
            }
            None
        })
        .await
        .ok()
        .flatten()
        .expect("an answer to the WebSocket grasp");
        self.log
            .push(format!("ws grasp {close_to:?}: {}", answer["type"]));
        (answer["type"] == "grasp_started")
            .then(|| answer["grasp"]["id"].as_u64().expect("a grasp id"))
    }

    async fn power_cycle(&mut self, id: u8) {
        self.b.sim.inject(Fault::PowerCycle { dev_id: id });
        self.log.push(format!("power cycle {id}"));
        self.not_under(id);
    }

    /// An e-stop with a move or a target in flight beside it.
    async fn estop_race(&mut self, id: u8) {
        let handle = self.b.handle.clone();
        let estop = tokio::spawn(async move { handle.estop().await });
        tokio::time::sleep(Duration::from_millis(self.rng.below(4))).await;
        if self.rng.below(2) == 0 {
            self.move_joints(&[id], 1500).await;
        } else {
            self.target(id).await;
        }
        let _ = estop.await;
        self.log.push("estop (raced)".into());
        self.under = Default::default();
    }

    async fn step(&mut self) {
        let id = self.rng.joint();
        match self.rng.below(100) {
            0..=17 => self.enable(id).await,
            18..=22 => self.disable(id).await,
            23..=26 => self.estop().await,
            27..=33 => {
                let speed = self.rng.below(3) == 0;
                self.mode(id, speed).await
            }
            34..=45 => self.target(id).await,
            46..=48 => self.grasp().await,
            49..=51 => self.grasp_taken_over_by_a_move().await,
            52..=54 => self.slow_target_then_move(id).await,
            55..=56 => self.grasp_unplugged().await,
            // Moves outlast several steps: what happens to them meanwhile
            // (an e-stop, a disable, a mode change) is the point.
            57..=66 => {
                let ms = 300 + self.rng.below(2700);
                self.move_joints(&[id], ms).await
            }
            67..=72 => self.move_joints(&[1, 2], 1500).await,
            73..=78 => self.pose_go().await,
            79..=86 => self.stream(id).await,
            87..=89 => self.power_cycle(id).await,
            90..=94 => self.homing(id).await,
            _ => self.estop_race(id).await,
        }
        self.fence().await;
        if std::env::var_os("JOINTD_SAFETY_TRACE").is_some() {
            for id in JOINTS {
                let d = self.device(id);
                eprintln!(
                    "  after `{}`: joint {id} enabled {} angle {:.2} target {:.2}",
                    self.log.last().map_or("", |s| s.as_str()),
                    d.enabled,
                    d.angle_deg,
                    d.target_deg
                );
            }
        }
        self.check();
    }
}

/// A server message saying a watchdog fired.
fn is_watchdog(m: &Message) -> bool {
    matches!(m, Message::Text(t) if t.contains("\"watchdog\"") && t.contains("\"why\""))
}

/// The type of the server's answer to message `seq` (`ack` or `error`),
/// and whether a watchdog fired meanwhile.
async fn reply_to<S>(ws: &mut S, seq: u64) -> (Option<String>, bool)
where
    S: StreamExt<Item = Result<Message, tokio_tungstenite::tungstenite::Error>> + Unpin,
{
    let mut fired = false;
    let wait = async {
        while let Some(Ok(m)) = ws.next().await {
            fired |= is_watchdog(&m);
            if let Message::Text(t) = m {
                let v: Value = serde_json::from_str(t.as_str()).ok()?;
                if v["ref_seq"] == seq {
                    return v["type"].as_str().map(str::to_owned);
                }
            }
        }
        None
    };
    let reply = tokio::time::timeout(WAIT, wait).await.ok().flatten();
    (reply, fired)
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

async fn run_seed(seed: u64, steps: u64) {
    let b = start(3, None).await;
    let hands = jointd::hands::resolve(
        &[jointd::hands::HandConfig {
            name: "h".into(),
            joints: vec![jointd::hands::HandJoints {
                bus: "sim0".into(),
                ids: jointd::hands::Ids::List(vec![1, 2]),
                names: vec!["a".into(), "b".into()],
            }],
        }],
        &["sim0".to_string()],
    )
    .expect("a hand");
    let store = jointd::hands::StateStore::open(hands, None).expect("store");
    let options = jointd::control::Options {
        hands: Some(std::sync::Arc::new(store)),
        ..Default::default()
    };
    assert!(b.server_state.control().set_options(options).is_ok());
    let mut w = World {
        b,
        rng: Rng(seed.max(1)),
        seed,
        log: Vec::new(),
        admitted: Default::default(),
        under: Default::default(),
        after_outage: Default::default(),
    };
    for _ in 0..steps {
        w.step().await;
    }
    // What the run exercised: each kind of step, and how many were accepted.
    let mut kinds: std::collections::BTreeMap<&str, (u32, u32)> = Default::default();
    for line in &w.log {
        let kind = line.split([' ', ':']).next().unwrap_or("?");
        let e = kinds.entry(kind).or_default();
        e.0 += 1;
        e.1 += u32::from(
            line.contains(": 20") || line.contains("accepted") && !line.contains(" 0 accepted"),
        );
    }
    eprintln!("seed {seed}: (steps, accepted) by kind {kinds:?}");
    if std::env::var_os("JOINTD_SAFETY_LOG").is_some() {
        eprintln!("{}", w.log.join("\n"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_joint_moves_only_toward_what_was_admitted_since_its_last_enable() {
    let steps = env_u64("JOINTD_SAFETY_STEPS", 60);
    let seeds: Vec<u64> = match std::env::var("JOINTD_SAFETY_SEED") {
        Ok(s) => vec![s.parse().expect("JOINTD_SAFETY_SEED is a number")],
        Err(_) => {
            let base = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.as_nanos() as u64);
            (0..env_u64("JOINTD_SAFETY_SEEDS", 5))
                .map(|k| base.wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15)))
                .collect()
        }
    };
    for seed in seeds {
        eprintln!("safety seed {seed} ({steps} steps)");
        run_seed(seed, steps).await;
    }
}
