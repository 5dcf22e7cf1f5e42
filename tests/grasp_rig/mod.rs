//! A hand of three simulated fingers for the grasp tests: joints 1..=3 of
//! `sim0` named `a`, `b`, `c` in hand `h`, enabled and running, with the
//! simulator's objects as each test places them. Joint 2 has soft limits
//! of ±45° (the harness's).
#![allow(dead_code)]

use jointd::protocol::params::index;
use jointd::protocol::status::fsm;
use jointd::sim::SimObject;
use serde_json::{json, Value};

use crate::support::sim_bus::{start_sim_with, SimBus, WAIT};

/// The factory current limit (MAX_CUR raw).
pub const FACTORY_MAX_CUR: u16 = 4368;

pub async fn hand(objects: &[(u8, f64, f64)]) -> SimBus {
    hand_on("2.0.1", objects).await
}

/// [`hand`] on devices running `firmware` (`jointd sim --firmware` syntax).
pub async fn hand_on(firmware: &str, objects: &[(u8, f64, f64)]) -> SimBus {
    let objects: Vec<SimObject> = objects
        .iter()
        .map(|&(id, at_deg, nm_per_deg)| SimObject {
            id,
            at_deg,
            nm_per_deg,
        })
        .collect();
    let b = start_sim_with(3, None, firmware, |sim| sim.objects = objects, |_| {}).await;
    let hands = jointd::hands::resolve(
        &[jointd::hands::HandConfig {
            name: "h".into(),
            joints: vec![jointd::hands::HandJoints {
                bus: "sim0".into(),
                ids: jointd::hands::Ids::List(vec![1, 2, 3]),
                names: vec!["a".into(), "b".into(), "c".into()],
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
    b.server
        .post(
            "/api/v1/buses/sim0/control/enable",
            json!({"ids": [1, 2, 3]}),
        )
        .await
        .ok();
    for id in 1..=3 {
        b.wait_fsm(id, fsm::RUN).await;
    }
    b
}

/// Starts a grasp of hand `h`; its id (after checking 202 + Location).
pub async fn grasp(b: &SimBus, body: Value) -> u64 {
    let r = b.server.post("/api/v1/hands/h/grasp", body).await;
    assert_eq!(r.status.as_u16(), 202, "{}", r.body);
    let id = r.body["id"].as_u64().expect("an id");
    let location = r.headers.get("location").and_then(|v| v.to_str().ok());
    assert_eq!(location, Some(format!("/api/v1/grasps/{id}").as_str()));
    id
}

/// Polls grasp `id` until `ok` holds for its view; that view.
pub async fn wait_grasp(b: &SimBus, id: u64, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
    b.wait_view(&format!("/api/v1/grasps/{id}"), WAIT * 2, what, ok)
        .await
}

/// Finger `joint` of a grasp view.
pub fn finger<'a>(view: &'a Value, joint: &str) -> &'a Value {
    view["fingers"]
        .as_array()
        .and_then(|f| f.iter().find(|f| f["joint"] == joint))
        .unwrap_or_else(|| panic!("no finger {joint} in {view}"))
}

pub fn state_of(view: &Value, joint: &str) -> String {
    finger(view, joint)["state"]
        .as_str()
        .unwrap_or("?")
        .to_owned()
}

/// The simulated device's current limit (MAX_CUR raw) right now.
pub fn sim_limit(b: &SimBus, id: u8) -> u16 {
    b.sim.device(id).expect("device").params.raw(index::MAX_CUR)
}

/// The current limit as the config API reads it from the device, raw.
pub async fn api_limit(b: &SimBus, id: u8) -> u64 {
    let c = b
        .server
        .get(&format!("/api/v1/buses/sim0/devices/{id}/config"))
        .await;
    c.ok()["max_current_a"]["raw"].as_u64().expect("raw limit")
}

/// Every finger ended with its limit restored, on the device and as the
/// config API reads it.
pub async fn limits_restored(b: &SimBus, view: &Value) {
    for f in view["fingers"].as_array().expect("fingers") {
        assert_eq!(f["current_limit_restored"], true, "{f}");
        let id = f["id"].as_u64().expect("id") as u8;
        assert_eq!(sim_limit(b, id), FACTORY_MAX_CUR, "joint {id}");
        assert_eq!(
            api_limit(b, id).await,
            u64::from(FACTORY_MAX_CUR),
            "joint {id}"
        );
    }
}
