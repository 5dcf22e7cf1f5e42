//! Load shedding: at most [`MAX_IN_FLIGHT`] requests are handled at once;
//! one more is answered 503 (`overloaded`, Retry-After) at once instead of
//! queueing behind the others. An e-stop is never shed nor counted: a
//! flood of other requests cannot keep it out, and `/healthz` is not
//! either, so a probe does not restart a daemon that is only busy.

use std::sync::Arc;

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tokio::sync::Semaphore;

use crate::http::error::ApiError;
use crate::http::paths::HEALTHZ_PATH;

/// Requests handled at once, at most. Far above what a dashboard and a few
/// clients make (each waits for its answer); a flood meets it.
pub(crate) const MAX_IN_FLIGHT: usize = 128;

/// The places of the requests being handled.
#[derive(Clone)]
pub(crate) struct InFlight(Arc<Semaphore>);

impl InFlight {
    pub(crate) fn new(limit: usize) -> Self {
        Self(Arc::new(Semaphore::new(limit)))
    }
}

/// `POST /api/v1/estop` and `POST /api/v1/buses/{bus}/estop`.
pub(crate) fn is_estop(path: &str) -> bool {
    if path == "/api/v1/estop" {
        return true;
    }
    path.strip_prefix("/api/v1/buses/")
        .and_then(|rest| rest.strip_suffix("/estop"))
        .is_some_and(|bus| !bus.is_empty() && !bus.contains('/'))
}

/// The middleware: a place, or 503 now.
pub(crate) async fn shed(State(places): State<InFlight>, req: Request, next: Next) -> Response {
    let path = req.uri().path();
    if is_estop(path) || path == HEALTHZ_PATH {
        return next.run(req).await;
    }
    match places.0.clone().try_acquire_owned() {
        Ok(place) => {
            let resp = next.run(req).await;
            drop(place);
            resp
        }
        Err(_) => ApiError::overloaded(MAX_IN_FLIGHT).into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::routing::{get, post};
    use axum::Router;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Handlers that wait until the gate opens, counting who came in.
    #[derive(Clone, Default)]
    struct Gate {
        open: Arc<tokio::sync::Notify>,
        inside: Arc<AtomicUsize>,
        came: Arc<tokio::sync::Notify>,
    }

    async fn held(State(g): State<Gate>) -> &'static str {
        let opened = g.open.notified();
        g.inside.fetch_add(1, Ordering::SeqCst);
        g.came.notify_waiters();
        opened.await;
        "done"
    }

    async fn until_inside(g: &Gate, n: usize) {
        loop {
            let came = g.came.notified();
            if g.inside.load(Ordering::SeqCst) >= n {
                return;
            }
            came.await;
        }
    }

    #[tokio::test]
    async fn a_request_over_the_limit_is_shed_and_an_estop_never_is() {
        let gate = Gate::default();
        let app = Router::new()
            .route("/slow", get(held))
            .route("/api/v1/estop", post(held))
            .with_state(gate.clone())
            .layer(axum::middleware::from_fn_with_state(InFlight::new(2), shed));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        tokio::spawn(async move { axum::serve(listener, app).await });
        let client = reqwest::Client::new();
        let slow = || tokio::spawn(client.get(format!("{base}/slow")).send());
        let held_two = [slow(), slow()];
        until_inside(&gate, 2).await;
        let shed = client.get(format!("{base}/slow")).send().await.unwrap();
        assert_eq!(shed.status(), 503);
        assert_eq!(shed.headers()["retry-after"], "1");
        let body = shed.text().await.unwrap();
        assert!(body.contains("urn:jointd:problem:overloaded"), "{body}");
        // The e-stop goes in past the limit.
        let estop = tokio::spawn(client.post(format!("{base}/api/v1/estop")).send());
        until_inside(&gate, 3).await;
        gate.open.notify_waiters();
        assert_eq!(estop.await.unwrap().unwrap().status(), 200);
        for h in held_two {
            assert_eq!(h.await.unwrap().unwrap().status(), 200);
        }
        // The places came back.
        let again = tokio::spawn(client.get(format!("{base}/slow")).send());
        until_inside(&gate, 4).await;
        gate.open.notify_waiters();
        assert_eq!(again.await.unwrap().unwrap().status(), 200);
    }

    #[test]
    fn only_the_estop_routes_are_estops() {
        assert!(is_estop("/api/v1/estop"));
        assert!(is_estop("/api/v1/buses/sim0/estop"));
        assert!(!is_estop("/api/v1/buses//estop"));
        assert!(!is_estop("/api/v1/buses/a/b/estop"));
        assert!(!is_estop("/api/v1/estop/x"));
        assert!(!is_estop("/api/v1/buses/sim0/devices"));
    }
}
