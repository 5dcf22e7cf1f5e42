//! A web page the user visits must not move the hand. Each attack
//! is sent as the browser would send it against the API in front of the
//! real bus engine and the simulator; each must be refused and leave the
//! joint where it was, while the same request from the dashboard's origin
//! or from a client that sends no `Origin` (curl, scripts) still works.

mod support;

use futures_util::{SinkExt, StreamExt};
use reqwest::Method;
use serde_json::{json, Value};
use tokio_tungstenite::connect_async;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};

use jointd::protocol::status::fsm;
use support::sim_bus::{self, SimBus, WAIT};

const DEV: &str = "/api/v1/buses/sim0/devices";
const EVIL: &str = "http://evil.example";

/// What a refused attack must leave untouched on the simulated device.
#[derive(Debug, PartialEq)]
struct Pose {
    enabled: bool,
    fsm: u8,
    zero_deg: f64,
    target_deg: f64,
}

fn pose(bus: &SimBus, id: u8) -> Pose {
    let d = bus.sim.device(id).expect("simulated device");
    Pose {
        enabled: d.enabled,
        fsm: d.fsm,
        zero_deg: d.zero_deg,
        target_deg: d.target_deg,
    }
}

/// The "simple" cross-site requests a page can send without a CORS
/// preflight: no body, text/plain, form-encoded.
fn simple_posts() -> Vec<(String, Option<&'static str>, Option<&'static str>)> {
    vec![
        (format!("{DEV}/1/enable"), None, None),
        (format!("{DEV}/1/enable"), Some("text/plain"), Some("{}")),
        (
            format!("{DEV}/1/rezero"),
            Some("application/x-www-form-urlencoded"),
            Some("a=b"),
        ),
        (format!("{DEV}/1/config/persist"), None, None),
        ("/api/v1/estop".to_owned(), Some("text/plain"), Some("stop")),
        ("/api/v1/buses/sim0/control/enable".to_owned(), None, None),
    ]
}

async fn post_as(
    bus: &SimBus,
    path: &str,
    browser: &[(&str, &str)],
    content_type: Option<&str>,
    body: Option<&str>,
) -> support::http::Resp {
    let mut headers = browser.to_vec();
    if let Some(ct) = content_type {
        headers.push(("content-type", ct));
    }
    bus.server.browser(Method::POST, path, &headers, body).await
}

#[tokio::test]
async fn cross_site_simple_posts_are_refused_and_the_joint_does_not_move() {
    let bus = sim_bus::start(2, None).await;
    let before = pose(&bus, 1);
    assert!(!before.enabled);
    let foreign: [&[(&str, &str)]; 4] = [
        &[("origin", EVIL), ("sec-fetch-site", "cross-site")],
        &[("origin", "null")],
        // Another port on the same host is another origin (same-site).
        &[
            ("origin", "http://127.0.0.1:1"),
            ("sec-fetch-site", "same-site"),
        ],
        // A browser that sends no Origin but says where the page is.
        &[("sec-fetch-site", "cross-site")],
    ];
    for headers in foreign {
        for (path, ct, body) in simple_posts() {
            let r = post_as(&bus, &path, headers, ct, body).await;
            let p = r.problem(403);
            assert_eq!(p["type"], "urn:jointd:problem:foreign-origin", "{path}");
        }
        let r = bus
            .server
            .browser(
                Method::PUT,
                &format!("{DEV}/1/target"),
                &[headers, &[("content-type", "application/json")]].concat(),
                Some(r#"{"position_deg": 30}"#),
            )
            .await;
        r.problem(403);
    }
    assert_eq!(pose(&bus, 1), before, "a refused request reached the joint");
    // Reads stay open to any page's navigation (the browser hides the answer).
    bus.server
        .browser(Method::GET, DEV, &[("origin", EVIL)], None)
        .await
        .ok();

    // The dashboard: its own origin, as the browser sends it.
    let own = bus.server.origin();
    let dashboard = [("origin", own.as_str()), ("sec-fetch-site", "same-origin")];
    post_as(&bus, &format!("{DEV}/1/enable"), &dashboard, None, None)
        .await
        .ok();
    bus.wait_fsm(1, fsm::RUN).await;
    assert!(bus.sim.device(1).unwrap().enabled);
    // curl / Python: no Origin at all.
    bus.server
        .post_empty(&format!("{DEV}/1/disable"))
        .await
        .ok();
    bus.wait_fsm(1, fsm::READY).await;
    assert!(!bus.sim.device(1).unwrap().enabled);
}

fn ws_request(
    bus: &SimBus,
    headers: &[(&str, &str)],
) -> tokio_tungstenite::tungstenite::handshake::client::Request {
    let url = format!("{}/api/v1/ws", bus.server.base.replace("http://", "ws://"));
    let mut req = url.into_client_request().expect("request");
    for (name, value) in headers {
        let name: tokio_tungstenite::tungstenite::http::HeaderName =
            name.parse().expect("header name");
        req.headers_mut()
            .insert(name, value.parse().expect("header value"));
    }
    req
}

/// The first message of `kind` on a connection, within [`WAIT`].
async fn next_of<S>(ws: &mut S, kind: &str) -> Value
where
    S: futures_util::Stream<Item = Result<Message, WsError>> + Unpin,
{
    let found = tokio::time::timeout(WAIT, async {
        while let Some(Ok(msg)) = ws.next().await {
            if let Message::Text(text) = msg {
                let v: Value = serde_json::from_str(text.as_str()).expect("JSON");
                if v["type"] == kind {
                    return v;
                }
            }
        }
        panic!("connection closed before {kind}");
    })
    .await;
    found.unwrap_or_else(|_| panic!("no {kind} within {WAIT:?}"))
}

#[tokio::test]
async fn foreign_websocket_upgrade_is_refused_and_setpoints_never_arrive() {
    let bus = sim_bus::start(2, None).await;
    bus.server.post_empty(&format!("{DEV}/1/enable")).await.ok();
    bus.wait_fsm(1, fsm::RUN).await;
    let before = pose(&bus, 1);
    for headers in [
        vec![("origin", EVIL)],
        vec![
            ("origin", "http://localhost:3000"),
            ("sec-fetch-site", "same-site"),
        ],
        vec![("sec-fetch-site", "cross-site")],
    ] {
        match connect_async(ws_request(&bus, &headers)).await {
            Err(WsError::Http(resp)) => assert_eq!(resp.status(), 403, "{headers:?}"),
            other => panic!(
                "{headers:?}: expected 403, got {:?}",
                other.map(|_| "an open socket")
            ),
        }
    }
    assert_eq!(pose(&bus, 1), before, "a refused socket moved the joint");

    // The dashboard's page opens it from its own origin and streams.
    let own = bus.server.origin();
    let (mut ws, _) = connect_async(ws_request(&bus, &[("origin", own.as_str())]))
        .await
        .expect("same-origin socket");
    next_of(&mut ws, "welcome").await;
    let batch = json!({"type": "setpoints", "seq": 1, "ack": true,
        "targets": [{"id": 1, "position_deg": 20.0}]});
    ws.send(Message::text(batch.to_string()))
        .await
        .expect("send");
    next_of(&mut ws, "ack").await;
    let moved = tokio::time::timeout(WAIT, async {
        while bus.sim.device(1).unwrap().target_deg == before.target_deg {
            tokio::time::sleep(std::time::Duration::from_millis(10)).await;
        }
    })
    .await;
    assert!(
        moved.is_ok(),
        "the dashboard's setpoint never reached the joint"
    );
    // A script sends no Origin at all.
    let (mut ws, _) = connect_async(ws_request(&bus, &[]))
        .await
        .expect("script socket");
    next_of(&mut ws, "welcome").await;
}

#[tokio::test]
async fn dns_rebinding_host_is_refused_for_reads_and_writes() {
    let bus = sim_bus::start(1, None).await;
    let before = pose(&bus, 1);
    let port = bus
        .server
        .authority()
        .rsplit(':')
        .next()
        .unwrap()
        .to_owned();
    let evil_host = format!("evil.example:{port}");
    let evil_origin = format!("http://{evil_host}");
    // Rebinding: the page's origin is evil.example, so to the browser the
    // request is same-origin; only the Host header tells.
    let rebound = [
        ("host", evil_host.as_str()),
        ("origin", evil_origin.as_str()),
        ("sec-fetch-site", "same-origin"),
    ];
    for (method, path) in [
        (Method::GET, "/api/v1/buses".to_owned()),
        (Method::GET, format!("{DEV}/1")),
        (Method::GET, "/openapi.json".to_owned()),
        (Method::GET, "/".to_owned()),
        (Method::POST, format!("{DEV}/1/enable")),
        (Method::POST, "/api/v1/estop".to_owned()),
    ] {
        let r = bus
            .server
            .browser(method.clone(), &path, &rebound, None)
            .await;
        let p = r.problem(421);
        assert_eq!(
            p["type"], "urn:jointd:problem:unknown-host",
            "{method} {path}"
        );
    }
    assert_eq!(pose(&bus, 1), before, "a rebinding page reached the joint");
    // Container probes use whatever name their network gives.
    bus.server
        .browser(
            Method::GET,
            "/healthz",
            &[("host", evil_host.as_str())],
            None,
        )
        .await
        .ok();
    // Loopback names with any port (a port mapping changes it) work.
    for host in [
        format!("localhost:{port}"),
        "127.0.0.1".into(),
        "[::1]:9".into(),
    ] {
        bus.server
            .browser(
                Method::GET,
                "/api/v1/buses",
                &[("host", host.as_str())],
                None,
            )
            .await
            .ok();
    }
    let own = format!("http://localhost:{port}");
    let as_dashboard = [("host", &*format!("localhost:{port}")), ("origin", &*own)]
        .map(|(k, v)| (k, v.to_owned()));
    let headers: Vec<(&str, &str)> = as_dashboard.iter().map(|(k, v)| (*k, v.as_str())).collect();
    bus.server
        .browser(Method::POST, &format!("{DEV}/1/enable"), &headers, None)
        .await
        .ok();
}

/// The API on a scripted bus with these allow-lists.
async fn fake_with(
    token: Option<&str>,
    hosts: &[&str],
    origins: &[&str],
) -> (support::fake_bus::FakeBus, support::http::Server) {
    use jointd::http::policy::RequestPolicy;
    use jointd::http::state::HttpOptions;
    let bus = support::fake_bus::FakeBus::new("fake", &[1, 2]);
    let state = jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            vec![bus.handle.clone()],
            Default::default(),
        )),
        token.map(str::to_owned),
    );
    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let policy = RequestPolicy::new(None, &own(hosts), &own(origins), 1024 * 1024).unwrap();
    let options = HttpOptions {
        policy,
        ..Default::default()
    };
    assert!(state.set_options(options).is_ok());
    let mut server = support::http::serve(state).await;
    if let Some(t) = token {
        server = server.with_token(t);
    }
    (bus, server)
}

#[tokio::test]
async fn allowed_origins_and_hosts_extend_the_guards() {
    let (bus, s) = fake_with(None, &["robot-pc"], &["http://robot-pc:3000"]).await;
    let enable = "/api/v1/buses/fake/devices/1/enable";
    // A dashboard served elsewhere, allowed by config: another site by design.
    let elsewhere = [
        ("origin", "http://robot-pc:3000"),
        ("sec-fetch-site", "cross-site"),
    ];
    let r = s.browser(Method::POST, enable, &elsewhere, None).await;
    r.ok();
    assert_eq!(
        r.headers["access-control-allow-origin"],
        "http://robot-pc:3000"
    );
    // Its preflight (a JSON PUT with the token header) is answered.
    let preflight = [
        ("origin", "http://robot-pc:3000"),
        ("access-control-request-method", "PUT"),
        (
            "access-control-request-headers",
            "authorization,content-type",
        ),
    ];
    let r = s
        .browser(
            Method::OPTIONS,
            "/api/v1/buses/fake/devices/1/target",
            &preflight,
            None,
        )
        .await;
    assert!(r.status.is_success(), "{:?}", r);
    assert_eq!(
        r.headers["access-control-allow-origin"],
        "http://robot-pc:3000"
    );
    let methods = r.headers["access-control-allow-methods"].to_str().unwrap();
    assert!(methods.contains("PUT"), "{methods}");
    // Nobody else's.
    let foreign = [("origin", EVIL), ("access-control-request-method", "PUT")];
    let r = s
        .browser(
            Method::OPTIONS,
            "/api/v1/buses/fake/devices/1/target",
            &foreign,
            None,
        )
        .await;
    assert!(r.headers.get("access-control-allow-origin").is_none());
    // Not its neighbour on another port.
    s.browser(
        Method::POST,
        enable,
        &[("origin", "http://robot-pc:3001")],
        None,
    )
    .await
    .problem(403);
    // The allowed host name, any port, and its own origin.
    let host = [
        ("host", "robot-pc:8080"),
        ("origin", "http://robot-pc:8080"),
    ];
    s.browser(Method::POST, enable, &host, None).await.ok();
    s.browser(Method::GET, "/api/v1/buses", &[("host", "Robot-PC.")], None)
        .await
        .ok();
    s.browser(
        Method::GET,
        "/api/v1/buses",
        &[("host", "robot-pc.evil.example")],
        None,
    )
    .await
    .problem(421);
    assert_eq!(
        bus.script().log.iter().filter(|l| **l == "enable").count(),
        2
    );
    let (_bus, any) = fake_with(None, &["*"], &[]).await;
    any.browser(
        Method::GET,
        "/api/v1/buses",
        &[("host", "whatever.example")],
        None,
    )
    .await
    .ok();
}

#[tokio::test]
async fn the_websocket_token_is_percent_decoded() {
    let token = "a/b+= c";
    let (_bus, s) = fake_with(Some(token), &[], &[]).await;
    let base = s.base.replace("http://", "ws://");
    // What the dashboard sends: encodeURIComponent(token).
    let url = format!("{base}/api/v1/ws?token=a%2Fb%2B%3D%20c");
    let (mut ws, _) = connect_async(url).await.expect("encoded token accepted");
    next_of(&mut ws, "welcome").await;
    // `+` is a plus, not a space (RFC 3986, not form encoding).
    let (mut ws, _) = connect_async(format!("{base}/api/v1/ws?token=a%2Fb+%3D%20c"))
        .await
        .expect("a literal plus");
    next_of(&mut ws, "welcome").await;
    for wrong in ["a%2Fb%2B%3D", "a%2Fb%20%3D%20c", "a%2Fb%2B%3D%2", "%zz"] {
        match connect_async(format!("{base}/api/v1/ws?token={wrong}")).await {
            Err(WsError::Http(resp)) => assert_eq!(resp.status(), 401, "{wrong}"),
            other => panic!("{wrong}: expected 401, got {:?}", other.map(|_| "a socket")),
        }
    }
}
