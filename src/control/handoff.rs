//! A move that takes a joint out of a holding grasp leaves only once the
//! grasp has handed the joint's current limit back. The grasp holds with a
//! reduced limit, and a joint held to it cannot follow a path at speed: it
//! would lag and the move would stall. The grasp's finger hands the limit
//! back once the move's first target is on the wire (where the joint
//! stands, so it never presses further in); when that happens depends on
//! when its task runs, which a busy host delays by hundreds of ms. So the
//! move takes the joint at once, holds it where it stands, and starts its
//! path when every such limit is back; not back within [`BOUND`], the move
//! is aborted and the joint stays held.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::control::books::grasps::Slot;
use crate::control::books::lock::lock;
use crate::control::joints::JointRef;
use crate::control::state::Control;
use crate::motion::{MoveState, RunningMove};

/// How long a move waits for the grasps it takes joints from.
pub(crate) const BOUND: Duration = Duration::from_secs(2);
/// How often the waiting move looks at the grasps' fingers.
const LOOK_EVERY: Duration = Duration::from_millis(2);

/// The fingers of running grasps that hold `joints` with a reduced
/// current limit not yet handed back.
pub(crate) fn pending(state: &Control, joints: &[JointRef]) -> Vec<Slot> {
    joints
        .iter()
        .filter_map(|j| state.grasps().reduced_limit(&j.bus, j.id))
        .collect()
}

/// True once every finger's limit is back (read back as it was).
fn handed_back(fingers: &[Slot]) -> bool {
    fingers.iter().all(|s| lock(s).current_limit_restored)
}

/// Waits (bounded) for `fingers` to hand their limits back, then starts
/// `mv` after `delay`; aborts it if they do not.
pub(crate) fn start_when_handed_back(mv: Arc<RunningMove>, fingers: Vec<Slot>, delay: Duration) {
    tokio::spawn(async move {
        let deadline = Instant::now() + BOUND;
        while !handed_back(&fingers) {
            if Instant::now() >= deadline || !mv.is_running() {
                let joints: Vec<String> = fingers
                    .iter()
                    .map(|s| {
                        let f = lock(s);
                        format!("{} of bus `{}`", f.id, f.bus)
                    })
                    .collect();
                let why = format!(
                    "the grasp holding joint {} did not hand its current limit back within {:?}",
                    joints.join(", "),
                    BOUND
                );
                if mv.end(MoveState::Aborted, why.clone()) {
                    tracing::warn!(move_id = mv.id, "{why}: move aborted, the joints held");
                }
                return;
            }
            tokio::time::sleep(LOOK_EVERY).await;
        }
        mv.begin_at(Instant::now() + delay);
    });
}
