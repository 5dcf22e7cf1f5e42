//! Scoped tokens, walked route by route: every route of the served
//! OpenAPI document has its scope placed, `docs/scopes.md` is that table,
//! and a token of each scope reaches exactly what its scope allows (the
//! e-stop: every token). Over the WebSocket, a read token may look and
//! stop, not move.

mod support;

use std::sync::Arc;

use futures_util::{SinkExt, StreamExt};
use reqwest::Method;
use serde_json::{json, Value};
use tokio_tungstenite::connect_async;
use tokio_tungstenite::tungstenite::Message;

use jointd::control::Control;
use jointd::http::scope::{needs, placed, Needs, Scope};
use jointd::http::tokens::{NamedToken, Tokens};
use jointd::http::AppState;
use support::fake_bus::FakeBus;
use support::http::{serve, Server};

const SCOPES_DOC: &str = "docs/scopes.md";

/// Every (method, route) of the served document.
async fn routes(server: &Server) -> Vec<(Method, String)> {
    let doc = server.get("/openapi.json").await.ok().clone();
    let mut out = Vec::new();
    for (path, ops) in doc["paths"].as_object().expect("paths") {
        for method in ops.as_object().expect("operations").keys() {
            if let Ok(m) = method.to_uppercase().parse::<Method>() {
                out.push((m, path.clone()));
            }
        }
    }
    out.sort_by(|a, b| (a.1.as_str(), a.0.as_str()).cmp(&(b.1.as_str(), b.0.as_str())));
    out
}

fn state_with_three_tokens(bus: &FakeBus) -> AppState {
    let control = Arc::new(Control::new(vec![bus.handle.clone()], Default::default()));
    let tokens = Tokens::new(vec![
        NamedToken::new("watcher", Scope::Read, "read-secret"),
        NamedToken::new("driver", Scope::Operate, "operate-secret"),
        NamedToken::new("engineer", Scope::Admin, "admin-secret"),
    ]);
    AppState::with_tokens(control, tokens)
}

fn secret(scope: Scope) -> &'static str {
    match scope {
        Scope::Read => "read-secret",
        Scope::Operate => "operate-secret",
        Scope::Admin => "admin-secret",
    }
}

/// The table docs/scopes.md holds, from the router.
fn table(routes: &[(Method, String)]) -> String {
    let mut out = String::from(
        "# Scopes by route\n\n\
         What each route needs of a token ([security.md](security.md#scoped-tokens)):\n\
         `read` looks, `operate` moves, `admin` configures; `any` is every valid token\n\
         (the e-stop). Written from the router by `tests/api_scopes.rs`\n\
         (`JOINTD_BLESS_SCOPES=1` rewrites it), so it cannot drift.\n\n\
         | method | route | scope |\n|---|---|---|\n",
    );
    for (m, r) in routes {
        let n = needs(m, Some(r));
        out.push_str(&format!("| {m} | `{r}` | {} |\n", n.name()));
    }
    out
}

#[tokio::test]
async fn every_route_has_its_scope_placed_and_the_doc_is_the_routers_table() {
    let bus = FakeBus::new("fake", &[1]);
    let server = serve(state_with_three_tokens(&bus))
        .await
        .with_token("read-secret");
    let routes = routes(&server).await;
    assert!(routes.len() > 40, "{} routes", routes.len());
    for (m, r) in &routes {
        let is_read = *m == Method::GET || *m == Method::HEAD;
        assert!(
            is_read || placed(m, r),
            "{m} {r} changes something and has no scope placed in http::scope"
        );
    }
    let want = table(&routes);
    if std::env::var_os("JOINTD_BLESS_SCOPES").is_some() {
        std::fs::write(SCOPES_DOC, &want).expect("write docs/scopes.md");
    }
    let have = std::fs::read_to_string(SCOPES_DOC).unwrap_or_default();
    assert_eq!(
        have, want,
        "docs/scopes.md is not the router's table: JOINTD_BLESS_SCOPES=1 cargo test --test api_scopes"
    );
}

/// A route's template with a value in each of its parameters.
fn concrete(route: &str) -> String {
    route
        .replace("{bus}", "fake")
        .replace("{id}", "1")
        .replace("{hand}", "nohand")
        .replace("{name}", "nopose")
}

#[tokio::test]
async fn each_token_reaches_what_its_scope_allows_and_every_token_stops() {
    let bus = FakeBus::new("fake", &[1]);
    let state = state_with_three_tokens(&bus);
    let base = serve(state.clone()).await;
    let routes = routes(&base.with_token("admin-secret")).await;
    for scope in Scope::ALL {
        let server = serve(state.clone()).await.with_token(secret(scope));
        for (m, r) in &routes {
            let body = (*m != Method::GET && *m != Method::DELETE).then(|| json!({}));
            let resp = server.call(m.clone(), &concrete(r), body).await;
            let need = needs(m, Some(r));
            let status = resp.status.as_u16();
            assert_ne!(status, 401, "{scope} token, {m} {r}: {}", resp.body);
            if need.allows(scope) {
                assert_ne!(status, 403, "{scope} token refused {m} {r}: {}", resp.body);
            } else {
                let p = resp.problem(403);
                assert!(
                    p["type"]
                        .as_str()
                        .is_some_and(|t| t.ends_with("insufficient-scope")),
                    "{m} {r}: {p}"
                );
                let detail = p["detail"].as_str().unwrap_or_default();
                assert!(
                    detail.contains(need.name()),
                    "says the scope it needed: {detail}"
                );
                assert!(!detail.contains("secret"), "never the token: {detail}");
            }
        }
    }
    // Every token may stop, the read token included.
    let watcher = serve(state.clone()).await.with_token("read-secret");
    let stop = watcher.call(Method::POST, "/api/v1/estop", None).await;
    assert_ne!(stop.status.as_u16(), 403, "{}", stop.body);
    assert_eq!(needs(&Method::POST, Some("/api/v1/estop")), Needs::AnyToken);
}

/// Who did it: a command is told in the bus's events with its token's
/// name (never the token), and the same command again within the second
/// is counted with the next one told, not told again.
#[tokio::test]
async fn a_command_is_in_the_events_with_its_tokens_name() {
    let bus = FakeBus::new("fake", &[1]);
    let mut events = bus.handle.events();
    let server = serve(state_with_three_tokens(&bus))
        .await
        .with_token("operate-secret");
    for _ in 0..3 {
        server
            .post("/api/v1/buses/fake/control/disable", json!({"ids": [1]}))
            .await;
    }
    // A read is no command.
    server.get("/api/v1/buses/fake").await;
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(10);
    let mut told = Vec::new();
    while told.is_empty() {
        let ev = tokio::time::timeout_at(deadline, events.recv())
            .await
            .expect("a command event in time")
            .expect("the bus's events");
        if let jointd::bus::handle::BusEvent::Command {
            by,
            command,
            outcome,
            repeats,
            ..
        } = ev
        {
            told.push((by, command, outcome, repeats));
        }
    }
    let (by, command, outcome, repeats) = &told[0];
    assert_eq!(by, "driver");
    assert_eq!(command, "POST /api/v1/buses/fake/control/disable");
    assert!(
        !outcome.is_empty() && !outcome.contains("secret"),
        "{outcome}"
    );
    assert_eq!(*repeats, 0, "the first is told at once");
    // The two repeats are held back (told with the next one after the second).
    while let Ok(ev) = events.try_recv() {
        assert!(
            !matches!(ev, jointd::bus::handle::BusEvent::Command { .. }),
            "a repeat within the second told again: {ev:?}"
        );
    }
}

#[tokio::test]
async fn the_caller_route_names_the_token_and_its_scope() {
    let bus = FakeBus::new("fake", &[1]);
    let server = serve(state_with_three_tokens(&bus))
        .await
        .with_token("operate-secret");
    let me = server.get("/api/v1/caller").await;
    let me = me.ok();
    assert_eq!(me["name"], "driver");
    assert_eq!(me["scope"], "operate");
    assert_eq!(me["auth"], true);
}

async fn ws(
    server: &Server,
    token: &str,
) -> tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>> {
    let url = format!(
        "{}/api/v1/ws?token={token}",
        server.base.replace("http://", "ws://")
    );
    let (mut socket, _) = connect_async(url).await.expect("connect");
    let welcome = socket.next().await.expect("welcome").expect("frame");
    assert!(welcome.to_text().unwrap_or_default().contains("welcome"));
    socket
}

/// The next reply quoting `seq`.
async fn reply_to(
    socket: &mut tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    seq: u64,
) -> Value {
    loop {
        let msg = socket.next().await.expect("open").expect("frame");
        let Ok(text) = msg.to_text() else { continue };
        let v: Value = serde_json::from_str(text).expect("json");
        if v["ref_seq"] == seq {
            return v;
        }
    }
}

#[tokio::test]
async fn over_the_websocket_a_read_token_looks_and_stops_and_may_not_move() {
    let bus = FakeBus::new("fake", &[1]);
    let server = serve(state_with_three_tokens(&bus)).await;
    let mut socket = ws(&server, "read-secret").await;
    socket
        .send(Message::text(
            json!({"type": "subscribe", "seq": 1}).to_string(),
        ))
        .await
        .expect("send");
    assert_eq!(reply_to(&mut socket, 1).await["type"], "subscribed");
    let batch = json!({"type": "setpoints", "seq": 2, "targets": [{"bus": "fake", "id": 1, "position_deg": 5.0}]});
    socket
        .send(Message::text(batch.to_string()))
        .await
        .expect("send");
    let refused = reply_to(&mut socket, 2).await;
    assert_eq!(refused["type"], "error");
    assert_eq!(refused["code"], "forbidden", "{refused}");
    assert!(refused["message"]
        .as_str()
        .unwrap_or_default()
        .contains("operate"));
    socket
        .send(Message::text(
            json!({"type": "estop", "seq": 3}).to_string(),
        ))
        .await
        .expect("send");
    assert_eq!(reply_to(&mut socket, 3).await["type"], "estopped");
}
