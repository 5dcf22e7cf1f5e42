//! The statuses the OpenAPI document describes on every route, and the
//! problems the request guards answer with before any handler runs.

/// Every failure status an operation may answer with, and what it means:
/// the OpenAPI document's shared responses (every operation).
pub(crate) const DOCUMENTED_STATUSES: [(&str, &str); 10] = [
    (
        "400",
        "Malformed request (JSON syntax, unparsable path or query)",
    ),
    ("401", "Missing or wrong bearer token"),
    ("404", "Unknown bus, device or route"),
    (
        "409",
        "Wrong device state, device refused, or preempted by an e-stop",
    ),
    ("415", "Body is not application/json"),
    (
        "422",
        "Value out of range or outside a soft limit; names the field and the range",
    ),
    (
        "502",
        "The device answered something other than what was asked (unexpected-reply), \
         or a write reads back another value (verify-mismatch)",
    ),
    (
        "503",
        "Bus down, request queue full, bus owner stopped, or too many requests at once \
         (overloaded: retry after Retry-After; e-stops are never refused for this)",
    ),
    (
        "504",
        "Device did not answer (device-timeout), or a write went out and its confirmation \
         was lost (write-unverified: it may or may not have taken effect; a config PATCH's \
         `partial` lists `written`, `unverified` and `not_written` per parameter)",
    ),
    ("500", "Internal error (a bug; never expected)"),
];

/// Statuses of the request guards, each documented only where it applies:
/// 403 on operations that change something, 413 on those with a body, 421
/// on all but `/healthz`.
pub(crate) const FORBIDDEN_ORIGIN: (&str, &str) = (
    "403",
    "A browser page of a foreign origin tried to change something (Origin / Sec-Fetch-Site)",
);
pub(crate) const BODY_TOO_LARGE: (&str, &str) = ("413", "Request body over max_body_bytes");
pub(crate) const UNKNOWN_HOST: (&str, &str) = (
    "421",
    "The Host header names no host of this daemon (DNS rebinding guard; see allowed_hosts)",
);
