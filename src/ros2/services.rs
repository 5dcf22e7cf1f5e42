//! A namespace's services, served as rmw_zenoh serves them (a queryable
//! on the service's key expression and an `SS` token; see [`super::keys`]):
//! `<ns>/enable` (`std_srvs/srv/SetBool`: `true` enables every joint of the
//! bus or hand, `false` disables them) and `<ns>/estop`
//! (`std_srvs/srv/Trigger`: the e-stop of the bus, or of every bus a
//! hand's joints are on). Both through the core's calls REST makes
//! (`Control::enable` / `disable` / `estop_buses`).
//! A hand's namespace (`namespace_by = "hand"`) has two more, both
//! `std_srvs/srv/Trigger`: `<hand>/grasp_release` releases the hand's
//! running grasp (each finger back to where it started, as REST's
//! `POST /api/v1/grasps/{id}/release` with `{}`) and `<hand>/grasp_stop`
//! stops it (each finger holds where it is, as `.../stop`); either answers
//! once the grasp ended, with every finger's state.
//! Each service has its own task, so an e-stop never waits behind an
//! enable still confirming or a release still opening.

use std::sync::Arc;

use tokio::sync::watch;
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::{Query, Queryable};

use super::audit;
use super::gripper;
use super::keys;
use crate::control::grasp::{self, ReleaseRequest};
use crate::control::Control;
use crate::record::joint_states::Scope;
use crate::rosmsg::bridge as msgs;

pub(super) type ServiceQueryable = Queryable<FifoChannelHandler<Query>>;

/// Which service a queryable serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Service {
    /// `std_srvs/srv/SetBool`.
    Enable,
    /// `std_srvs/srv/Trigger`.
    Estop,
    /// `std_srvs/srv/Trigger`: a hand's grasp released.
    GraspRelease,
    /// `std_srvs/srv/Trigger`: a hand's grasp stopped.
    GraspStop,
}

impl Service {
    /// Its name under the namespace, its DDS type and hash.
    pub(super) fn describe(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Self::Enable => ("enable", keys::SET_BOOL_TYPE, keys::SET_BOOL_HASH),
            Self::Estop => ("estop", keys::TRIGGER_TYPE, keys::TRIGGER_HASH),
            Self::GraspRelease => ("grasp_release", keys::TRIGGER_TYPE, keys::TRIGGER_HASH),
            Self::GraspStop => ("grasp_stop", keys::TRIGGER_TYPE, keys::TRIGGER_HASH),
        }
    }
}

/// Answers requests until the session closes.
pub(super) async fn serve(
    state: Arc<Control>,
    scope: Scope,
    service: Service,
    queryable: ServiceQueryable,
    key: String,
    mut closing: watch::Receiver<bool>,
) {
    loop {
        let query = tokio::select! {
            q = queryable.recv_async() => match q {
                Ok(q) => q,
                Err(_) => return,
            },
            // The guard `wait_for` returns is not `Send`: dropped at once.
            () = async { drop(closing.wait_for(|c| *c).await) } => return,
        };
        let payload = query
            .payload()
            .map(|p| p.to_bytes().into_owned())
            .unwrap_or_default();
        let (success, message) = match service {
            Service::Enable => match msgs::set_bool_request(&payload) {
                Ok(on) => set_enabled(&state, &scope, on).await,
                Err(e) => (false, format!("not a std_srvs/srv/SetBool request: {e}")),
            },
            Service::Estop => {
                // An e-stop is not refused for a malformed request.
                let _ = msgs::trigger_request(&payload);
                estop(&state, &scope).await
            }
            Service::GraspRelease | Service::GraspStop => match msgs::trigger_request(&payload) {
                Ok(()) => end_grasp(&state, &scope, service == Service::GraspRelease).await,
                Err(e) => (false, format!("not a std_srvs/srv/Trigger request: {e}")),
            },
        };
        tracing::info!(?scope, ?service, success, %message, "ROS 2: service called");
        let what = format!(
            "service /{}/{}",
            audit::namespace(&scope),
            service.describe().0
        );
        audit::tell(
            &state,
            audit::bus(&scope),
            &what,
            if success { "done" } else { "refused" },
        );
        reply(&query, &key, success, &message).await;
    }
}

/// The response, with the request's sequence number and client GID and
/// the time now, as rmw_zenoh's clients match replies to requests.
async fn reply(query: &Query, key: &str, success: bool, message: &str) {
    let (sequence, _, gid) = query
        .attachment()
        .and_then(|a| keys::parse_attachment(&a.to_bytes()))
        .unwrap_or((0, 0, [0; 16]));
    let now = i64::try_from(crate::record::joint_states::system_ns(
        std::time::SystemTime::now(),
    ))
    .unwrap_or(i64::MAX);
    let sent = query
        .reply(key, msgs::service_response(success, message))
        .attachment(keys::attachment(sequence, now, &gid))
        .await;
    if let Err(e) = sent {
        tracing::debug!(error = %e, "ROS 2: a service reply could not be sent");
    }
}

/// Each bus of the scope with the joints of it the scope has (`None`:
/// every joint of the bus); buses the daemon does not have are left out.
fn groups(state: &Control, scope: &Scope) -> Vec<(String, Option<Vec<u8>>)> {
    match scope {
        Scope::Bus(name) => state
            .reader(name)
            .map(|_| vec![(name.clone(), None)])
            .unwrap_or_default(),
        Scope::Hand { joints, .. } => {
            let mut out: Vec<(String, Vec<u8>)> = Vec::new();
            for (bus, id) in joints {
                match out.iter_mut().find(|(b, _)| b == bus) {
                    Some((_, ids)) => ids.push(*id),
                    None if state.reader(bus).is_ok() => out.push((bus.clone(), vec![*id])),
                    None => {}
                }
            }
            out.into_iter().map(|(b, ids)| (b, Some(ids))).collect()
        }
    }
}

/// Enables (or disables) every joint of the scope, bus by bus, through
/// the core's calls REST makes; success when every bus confirmed it.
async fn set_enabled(state: &Control, scope: &Scope, on: bool) -> (bool, String) {
    let verb = if on { "enabled" } else { "disabled" };
    let mut done = Vec::new();
    let mut failed = Vec::new();
    for (bus, ids) in groups(state, scope) {
        let what = match &ids {
            None => format!("every joint of bus `{bus}`"),
            Some(ids) => format!("joints {ids:?} of bus `{bus}`"),
        };
        let result = if on {
            state.enable(&bus, ids).await
        } else {
            state.disable(&bus, ids).await
        };
        match result {
            Ok(()) => done.push(what),
            Err(e) => failed.push(format!("{what}: {e}")),
        }
    }
    if failed.is_empty() && !done.is_empty() {
        (true, format!("{verb} {}", done.join(", ")))
    } else if done.is_empty() && failed.is_empty() {
        (false, "no joints here".into())
    } else {
        let mut msg = format!("not {verb}: {}", failed.join("; "));
        if !done.is_empty() {
            msg.push_str(&format!(" ({verb}: {})", done.join(", ")));
        }
        (false, msg)
    }
}

/// The e-stop of the scope's buses, as REST's `POST /buses/{bus}/estop`.
async fn estop(state: &Control, scope: &Scope) -> (bool, String) {
    let groups = groups(state, scope);
    let names: Vec<&str> = groups.iter().map(|(b, _)| b.as_str()).collect();
    let result = match state.estop_buses(&names).await {
        Ok(result) => result,
        Err(e) => return (false, format!("e-stop: {e}")),
    };
    let each: Vec<String> = result
        .buses
        .iter()
        .map(|b| match &b.error {
            None => format!(
                "bus `{}` stopped ({} confirmed, {} unconfirmed)",
                b.bus,
                b.confirmed.len(),
                b.unconfirmed.len()
            ),
            Some(e) => format!("bus `{}` NOT confirmed stopped: {e}", b.bus),
        })
        .collect();
    (result.stopped, format!("e-stop: {}", each.join("; ")))
}

/// Releases (or stops) the hand's running grasp; answers once it ended.
async fn end_grasp(state: &Control, scope: &Scope, release: bool) -> (bool, String) {
    let Scope::Hand { name, joints } = scope else {
        return (
            false,
            "grasps are per hand (namespace_by = \"hand\")".into(),
        );
    };
    let Some(id) = super::grasp_stream::running(state, joints) else {
        return (false, format!("no grasp running on hand `{name}`"));
    };
    let ended = if release {
        grasp::release(state, id, &ReleaseRequest::default()).await
    } else {
        grasp::stop(state, id).await
    };
    match ended {
        Ok(view) => gripper::ended(&view, if release { "released" } else { "stopped" }),
        Err(e) => (false, e.to_string()),
    }
}
