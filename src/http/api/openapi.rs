//! The OpenAPI document, generated from the handlers' `#[utoipa::path]`
//! annotations, served at `/openapi.json` with a Swagger UI at `/docs`
//! (vendored: no network needed). `openapi/openapi.json` in the repository is
//! a copy a test keeps equal to the served document.

use std::collections::BTreeMap;

use axum::Router;
use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
use utoipa::openapi::{ContentBuilder, Ref, RefOr, Response, ResponseBuilder};
use utoipa::{IntoResponses, Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_swagger_ui::SwaggerUi;

use crate::http::error::{
    Problem, BODY_TOO_LARGE, DOCUMENTED_STATUSES, FORBIDDEN_ORIGIN, PROBLEM_JSON, UNKNOWN_HOST,
};
use crate::http::paths::{DOCS_PATH, HEALTHZ_PATH, OPENAPI_PATH};
use crate::http::state::AppState;

pub(crate) const TAG_BUSES: &str = "buses";
pub(crate) const TAG_DEVICES: &str = "devices";
pub(crate) const TAG_CONTROL: &str = "control";
pub(crate) const TAG_CONFIG: &str = "configuration";
pub(crate) const TAG_ESTOP: &str = "emergency stop";
pub(crate) const TAG_HEALTH: &str = "health";
/// Name of the bearer security scheme in the document.
const BEARER_SCHEME: &str = "bearer";

#[derive(OpenApi)]
#[openapi(
    info(
        title = "jointd REST API",
        description = "Everything a user can do with a joint module, over HTTP. Angles are \
            output-shaft degrees, speeds rotor rpm (before the 568.81:1 gearbox), currents \
            amperes. Every failure is an RFC 9457 problem (application/problem+json). When the \
            daemon has a token, every request but /healthz needs `Authorization: Bearer <token>`. \
            A request whose Host header names no host of the daemon gets 421 (DNS-rebinding \
            guard); a change (any method but GET) from a browser page of a foreign origin gets \
            403; a body over max_body_bytes gets 413.",
        contact(name = "jointd developers"),
        license(name = "MIT OR Apache-2.0", identifier = "MIT OR Apache-2.0")
    ),
    servers(
        (url = "http://127.0.0.1:8080", description = "The daemon on this machine, default `--listen` address"),
    ),
    modifiers(&BearerAuth),
    // `PatchOutcomes`: the `partial` of a config PATCH that did not confirm everything.
    components(schemas(Problem, super::config_outcome::PatchOutcomes)),
    tags(
        (name = "buses", description = "Serial buses: state, stats, scan, baud"),
        (name = "devices", description = "Joint modules on a bus and their telemetry"),
        (name = "control", description = "Enable, disable, targets, mode, jog, re-zero"),
        (name = "configuration", description = "Parameters (INFO_03..06), persist, id change"),
        (name = "emergency stop", description = "Disable every device on every bus at once"),
        (name = "health", description = "Liveness, readiness, Prometheus metrics"),
    )
)]
struct ApiDoc;

/// Declares the optional bearer token and the shared failure responses.
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        let components = doc.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            BEARER_SCHEME,
            SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)),
        );
        add_problem_responses(components);
        // Required only when the daemon has a token: either no security or bearer.
        doc.security = Some(vec![
            utoipa::openapi::security::SecurityRequirement::new::<_, _, &str>(BEARER_SCHEME, []),
            utoipa::openapi::security::SecurityRequirement::default(),
        ]);
    }
}

/// Success examples recorded from `jointd --sim 2` (lists shortened), one
/// per operation, keyed `"<method> <path>"`. Kept beside the document so a
/// linter checks each against its schema.
const EXAMPLES_JSON: &str = include_str!("../../../openapi/examples.json");

/// Puts each operation's example of `json` on its first success response.
fn add_examples(doc: &mut utoipa::openapi::OpenApi, json: &str) {
    let Ok(serde_json::Value::Object(examples)) = serde_json::from_str(json) else {
        tracing::error!("openapi/examples.json is not a JSON object: examples left out");
        return;
    };
    for (path, item) in doc.paths.paths.iter_mut() {
        let ops = [
            ("get", &mut item.get),
            ("put", &mut item.put),
            ("post", &mut item.post),
            ("delete", &mut item.delete),
            ("patch", &mut item.patch),
        ];
        for (method, op) in ops {
            let Some(op) = op.as_mut() else { continue };
            let Some(example) = examples.get(&format!("{method} {path}")) else {
                continue;
            };
            let success = op
                .responses
                .responses
                .iter_mut()
                .find(|(s, _)| s.starts_with('2'));
            if let Some((_, RefOr::T(response))) = success {
                if let Some(content) = response.content.get_mut("application/json") {
                    content.example = Some(example.clone());
                }
            }
        }
    }
}

/// The failures any operation may answer with, each a [`Problem`].
pub(crate) struct ErrorResponses;

/// Name of the shared response component of a failure status.
fn problem_response_name(status: &str) -> String {
    format!("Problem{status}")
}

impl IntoResponses for ErrorResponses {
    /// References to the shared components, so the document lists each
    /// failure once.
    fn responses() -> BTreeMap<String, RefOr<Response>> {
        DOCUMENTED_STATUSES
            .iter()
            .map(|(status, _)| {
                let name = problem_response_name(status);
                let reference = Ref::new(format!("#/components/responses/{name}"));
                (status.to_string(), RefOr::Ref(reference))
            })
            .collect()
    }
}

/// The shared failure responses, each a [`Problem`].
fn add_problem_responses(components: &mut utoipa::openapi::Components) {
    let guards = [FORBIDDEN_ORIGIN, BODY_TOO_LARGE, UNKNOWN_HOST];
    for (status, description) in DOCUMENTED_STATUSES.into_iter().chain(guards) {
        let content = ContentBuilder::new()
            .schema(Some(Ref::from_schema_name("Problem")))
            .build();
        let response = ResponseBuilder::new()
            .description(description)
            .content(PROBLEM_JSON, content)
            .build();
        components
            .responses
            .insert(problem_response_name(status), RefOr::T(response));
    }
}

/// A reference to the shared response of a failure status.
fn problem_ref(status: &str) -> RefOr<Response> {
    let name = problem_response_name(status);
    RefOr::Ref(Ref::new(format!("#/components/responses/{name}")))
}

/// The guards' statuses, on the operations they apply to: 421 on every
/// route but `/healthz`, 403 on every method but GET, 413 where a body is
/// taken. Run on the document once the areas have added their routes.
fn add_guard_responses(doc: &mut utoipa::openapi::OpenApi) {
    use utoipa::openapi::HttpMethod;
    for (path, item) in doc.paths.paths.iter_mut() {
        let ops = [
            (HttpMethod::Get, &mut item.get),
            (HttpMethod::Put, &mut item.put),
            (HttpMethod::Post, &mut item.post),
            (HttpMethod::Delete, &mut item.delete),
            (HttpMethod::Patch, &mut item.patch),
        ];
        for (method, op) in ops {
            let Some(op) = op.as_mut() else { continue };
            let mut add = |(status, _): (&str, &str)| {
                op.responses
                    .responses
                    .insert(status.to_owned(), problem_ref(status));
            };
            if path != HEALTHZ_PATH {
                add(UNKNOWN_HOST);
            }
            if method != HttpMethod::Get {
                add(FORBIDDEN_ORIGIN);
            }
            if op.request_body.is_some() {
                add(BODY_TOO_LARGE);
            }
        }
    }
}

/// The document's head (info, tags, security, shared failures), before the
/// areas add their routes.
pub(crate) fn base() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
}

/// `/openapi.json` and the Swagger UI at `/docs`.
pub(crate) fn docs(mut doc: utoipa::openapi::OpenApi) -> Router<AppState> {
    finish(&mut doc);
    SwaggerUi::new(DOCS_PATH).url(OPENAPI_PATH, doc).into()
}

/// What the document gets once the areas have added their routes: the
/// guards' responses, the recorded examples, the crate version.
pub(crate) fn finish(doc: &mut utoipa::openapi::OpenApi) {
    add_guard_responses(doc);
    add_examples(doc, EXAMPLES_JSON);
    doc.info.version = env!("CARGO_PKG_VERSION").to_owned();
}

/// A document as pretty JSON, as checked in under `openapi/`.
pub(crate) fn to_json(doc: &utoipa::openapi::OpenApi) -> String {
    let mut text = doc
        .to_pretty_json()
        .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    text.push('\n');
    text
}
