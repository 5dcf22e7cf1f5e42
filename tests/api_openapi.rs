//! The checked-in OpenAPI document equals the one the daemon serves, and
//! the document keeps the promises the API makes (examples, problem shape).

mod support;

use jointd::http::api;
use serde_json::Value;
use support::http::serve;

const CHECKED_IN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json");

fn checked_in() -> Value {
    // `JOINTD_BLESS_OPENAPI=1 cargo test --test api_openapi` rewrites the file.
    if std::env::var_os("JOINTD_BLESS_OPENAPI").is_some() {
        std::fs::write(CHECKED_IN, api::document_json()).expect("write openapi.json");
    }
    let text = std::fs::read_to_string(CHECKED_IN).expect("openapi/openapi.json exists");
    serde_json::from_str(&text).expect("openapi/openapi.json is JSON")
}

#[tokio::test]
async fn checked_in_document_equals_the_served_one() {
    let server = serve(jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            Vec::new(),
            Default::default(),
        )),
        None,
    ))
    .await;
    let served = server.get("/openapi.json").await;
    assert!(served.status.is_success());
    assert_eq!(
        checked_in(),
        served.body,
        "openapi/openapi.json differs from the served document; \
         regenerate it with `cargo run -- openapi > openapi/openapi.json`"
    );
    // The text is exactly what `jointd openapi` prints, so diffs stay reviewable.
    let text = std::fs::read_to_string(CHECKED_IN).unwrap();
    assert_eq!(text, api::document_json());
}

#[tokio::test]
async fn docs_page_is_served() {
    let server = serve(jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            Vec::new(),
            Default::default(),
        )),
        None,
    ))
    .await;
    let page = server.get("/docs/").await;
    assert!(page.status.is_success(), "{}", page.status);
    assert!(page
        .body
        .as_str()
        .is_some_and(|html| html.contains("swagger")));
}

#[test]
fn every_operation_documents_examples_and_problem_responses() {
    let doc = checked_in();
    let paths = doc["paths"].as_object().expect("paths");
    assert!(paths.len() >= 25, "{} paths", paths.len());
    for (path, item) in paths {
        for (method, op) in item.as_object().unwrap() {
            let what = format!("{method} {path}");
            let responses = op["responses"].as_object().expect("responses");
            let ok = responses.keys().any(|k| k.starts_with('2'));
            assert!(ok, "{what}: no success response");
            if path != "/healthz" {
                for status in ["401", "404", "422", "503", "504"] {
                    let reference = responses[status]["$ref"].as_str().expect("a $ref");
                    let name = reference.rsplit('/').next().unwrap();
                    let shared = &doc["components"]["responses"][name];
                    let content = &shared["content"]["application/problem+json"];
                    assert!(content.is_object(), "{what}: {status} not a problem");
                }
            }
            // The guards' statuses, where they apply.
            let has = |status: &str| responses.contains_key(status);
            assert_eq!(has("421"), path != "/healthz", "{what}: 421");
            assert_eq!(has("403"), method != "get", "{what}: 403");
            assert_eq!(has("413"), op.get("requestBody").is_some(), "{what}: 413");
            if let Some(body) = op.get("requestBody") {
                let example = &body["content"]["application/json"]["example"];
                assert!(!example.is_null(), "{what}: request body has no example");
            }
            // What the linters ask of every operation: a
            // description beside the summary, and a success example.
            let description = op["description"].as_str().unwrap_or("");
            assert!(description.len() > 40, "{what}: no description");
            let success = responses
                .iter()
                .find(|(k, _)| k.starts_with('2'))
                .unwrap()
                .1;
            let has_example = success["content"]
                .as_object()
                .is_some_and(|c| c.values().any(|m| !m["example"].is_null()));
            assert!(has_example, "{what}: success response has no example");
        }
    }
}

#[test]
fn every_recorded_example_names_an_operation() {
    // A renamed route must not leave its example behind, silently unused.
    let doc = checked_in();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/openapi/examples.json"
    ))
    .expect("openapi/examples.json");
    let examples: Value = serde_json::from_str(&text).expect("examples.json is JSON");
    for key in examples.as_object().expect("an object").keys() {
        let (method, path) = key.split_once(' ').expect("\"<method> <path>\"");
        assert!(
            doc["paths"][path][method].is_object(),
            "example for no operation: {key}"
        );
    }
}

#[test]
fn the_document_names_its_servers_and_contact() {
    // Redocly's recommended rules refuse a document without `servers`.
    let doc = checked_in();
    let servers = doc["servers"].as_array().expect("servers");
    assert!(servers
        .iter()
        .any(|s| s["url"].as_str().is_some_and(|u| u.starts_with("http"))));
    assert!(doc["info"]["contact"].is_object(), "info.contact");
}
