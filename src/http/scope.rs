//! What each route needs of a token: `read` (look), `operate` (move),
//! `admin` (configure), or any valid token at all (the e-stop: whoever may
//! look may stop). Decided here once, from the method and the route as
//! the router matched it, for REST and for the WebSocket's messages alike;
//! `docs/scopes.md` is this table, written from the router by a test.

use std::fmt;

use axum::http::Method;
use serde::{Deserialize, Serialize};

/// A token's scope; each includes the ones below it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scope {
    /// `GET` everything, telemetry streams, metrics, the dashboard read-only.
    Read,
    /// Enable, disable, targets, moves, poses, homing, grasps, teleop
    /// streams, recordings.
    Operate,
    /// Device configuration, id, baud, flash, calibration writes, re-zero,
    /// the bus-wide configuration.
    Admin,
}

impl Scope {
    pub const ALL: [Scope; 3] = [Scope::Read, Scope::Operate, Scope::Admin];

    pub fn name(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Operate => "operate",
            Self::Admin => "admin",
        }
    }

    pub fn parse(text: &str) -> Option<Scope> {
        Self::ALL.into_iter().find(|s| s.name() == text)
    }
}

impl fmt::Display for Scope {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a request needs of its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    /// Any valid token (the e-stop).
    AnyToken,
    /// A token of this scope or above.
    Scope(Scope),
}

impl Needs {
    /// Whether a token of `scope` may.
    pub fn allows(self, scope: Scope) -> bool {
        match self {
            Self::AnyToken => true,
            Self::Scope(need) => scope >= need,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::AnyToken => "any",
            Self::Scope(s) => s.name(),
        }
    }
}

/// The routes that change something, with what they need; every other
/// route (every `GET`, the WebSocket upgrade) reads. A change not listed
/// here needs `admin`: a new route is refused to all but admin tokens
/// until it is placed here (the route test names it).
pub(crate) const CHANGES: &[(&str, &str, Needs)] = &[
    ("POST", "/api/v1/estop", Needs::AnyToken),
    ("POST", "/api/v1/buses/{bus}/estop", Needs::AnyToken),
    (
        "POST",
        "/api/v1/buses/{bus}/control/enable",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/control/disable",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/control/mode",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/control/targets",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/devices/{id}/enable",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/devices/{id}/disable",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/devices/{id}/jog",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/devices/{id}/mode",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/devices/{id}/target",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/scan",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/doctor",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/grasps/{id}/release",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/grasps/{id}/stop",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/hands/{hand}/grasp",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/hands/{hand}/poses/{name}",
        Needs::Scope(Scope::Operate),
    ),
    (
        "DELETE",
        "/api/v1/hands/{hand}/poses/{name}",
        Needs::Scope(Scope::Operate),
    ),
    (
        "POST",
        "/api/v1/hands/{hand}/poses/{name}/go",
        Needs::Scope(Scope::Operate),
    ),
    ("POST", "/api/v1/homing", Needs::Scope(Scope::Operate)),
    ("POST", "/api/v1/moves", Needs::Scope(Scope::Operate)),
    ("DELETE", "/api/v1/moves/{id}", Needs::Scope(Scope::Operate)),
    ("POST", "/api/v1/recordings", Needs::Scope(Scope::Operate)),
    (
        "DELETE",
        "/api/v1/recordings/{id}",
        Needs::Scope(Scope::Operate),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/baud",
        Needs::Scope(Scope::Admin),
    ),
    (
        "PATCH",
        "/api/v1/buses/{bus}/config",
        Needs::Scope(Scope::Admin),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/devices/{id}/calibration",
        Needs::Scope(Scope::Admin),
    ),
    (
        "DELETE",
        "/api/v1/buses/{bus}/devices/{id}/calibration",
        Needs::Scope(Scope::Admin),
    ),
    (
        "PATCH",
        "/api/v1/buses/{bus}/devices/{id}/config",
        Needs::Scope(Scope::Admin),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/devices/{id}/config/persist",
        Needs::Scope(Scope::Admin),
    ),
    (
        "PUT",
        "/api/v1/buses/{bus}/devices/{id}/id",
        Needs::Scope(Scope::Admin),
    ),
    (
        "POST",
        "/api/v1/buses/{bus}/devices/{id}/rezero",
        Needs::Scope(Scope::Admin),
    ),
];

/// Whether a change (`method` other than `GET`/`HEAD`) on `route` has its
/// scope placed in the table (one not placed needs `admin`).
pub fn placed(method: &Method, route: &str) -> bool {
    CHANGES
        .iter()
        .any(|(m, r, _)| *m == method.as_str() && *r == route)
}

/// What `method` on `route` needs: `route` is the router's template (e.g.
/// `/api/v1/moves/{id}`), `None` for a path no route matched (which then
/// answers 404 or 405 and changes nothing).
pub fn needs(method: &Method, route: Option<&str>) -> Needs {
    if *method == Method::GET || *method == Method::HEAD {
        return Needs::Scope(Scope::Read);
    }
    let Some(route) = route else {
        return Needs::Scope(Scope::Read);
    };
    CHANGES
        .iter()
        .find(|(m, r, _)| *m == method.as_str() && *r == route)
        .map_or(Needs::Scope(Scope::Admin), |(_, _, n)| *n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scopes_are_ordered_and_named() {
        assert!(Scope::Read < Scope::Operate && Scope::Operate < Scope::Admin);
        for s in Scope::ALL {
            assert_eq!(Scope::parse(s.name()), Some(s));
        }
        assert_eq!(Scope::parse("root"), None);
    }

    #[test]
    fn reads_look_operators_move_admins_configure_and_anyone_stops() {
        let get = needs(
            &Method::GET,
            Some("/api/v1/buses/{bus}/devices/{id}/config"),
        );
        assert_eq!(get, Needs::Scope(Scope::Read));
        let target = needs(
            &Method::PUT,
            Some("/api/v1/buses/{bus}/devices/{id}/target"),
        );
        assert!(!target.allows(Scope::Read) && target.allows(Scope::Operate));
        let config = needs(
            &Method::PATCH,
            Some("/api/v1/buses/{bus}/devices/{id}/config"),
        );
        assert!(!config.allows(Scope::Operate) && config.allows(Scope::Admin));
        let estop = needs(&Method::POST, Some("/api/v1/estop"));
        assert!(Scope::ALL.into_iter().all(|s| estop.allows(s)));
    }

    #[test]
    fn a_change_nobody_placed_needs_admin() {
        let n = needs(&Method::POST, Some("/api/v1/something/new"));
        assert_eq!(n, Needs::Scope(Scope::Admin));
    }
}
