//! The checked-in OpenAPI document equals the one the daemon serves, and
//! the document keeps the promises the API makes (examples, problem shape).

mod support;

use jointd::http::api;
use jointd::http::state_for;
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
    let server = serve(state_for(Vec::new())).await;
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
    let server = serve(state_for(Vec::new())).await;
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
        }
    }
}
