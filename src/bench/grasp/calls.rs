//! The bench's calls on the core for a grasp: its view, its release, and
//! the wait until every finger is back at rest.

use std::sync::Arc;
use std::time::Instant;

use super::setup::{FINGERS, REST_DEG, REST_DEG_S, RUN_WAIT, SAMPLE};
use crate::bench::args::BenchError;
use crate::control::books::grasps::GraspView;
use crate::control::grasp::{self, ReleaseRequest};
use crate::control::Control;
use crate::sim::SimHandle;

/// Releases grasp `id` and waits until every finger is back at rest where
/// it started (the release answers once a finger is within a degree of
/// it: the next grasp would start short of it, and each a little shorter).
pub(super) async fn release(
    control: &Arc<Control>,
    sim: &SimHandle,
    id: u64,
) -> Result<(), BenchError> {
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

pub(super) async fn released(control: &Arc<Control>, id: u64) -> Result<(), BenchError> {
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

pub(super) fn view_of(control: &Control, id: u64) -> Result<GraspView, BenchError> {
    grasp::get(control, id).map_err(|e| BenchError::Setup(e.to_string()))
}
