"""One hierarchy of errors for REST and WebSocket, all under `JointdError`.

A refusal of the daemon carries its RFC 9457 problem document (`problem`);
the class follows the HTTP status (REST) or the error code (WebSocket), so
`except Conflict` catches a joint in the wrong state from either. A daemon
that cannot be reached raises `NotConnected`.
"""

from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Type


@dataclass(frozen=True)
class Problem:
    """The `Problem` schema of openapi/openapi.json."""

    SCHEMA = "Problem"
    type: str
    title: str
    status: int
    detail: str
    field: Optional[str] = None
    allowed: Optional[Dict[str, Any]] = None
    partial: Optional[Any] = None

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "Problem":
        return cls(type=str(data.get("type", "")), title=str(data.get("title", "")),
                   status=int(data.get("status", 0)), detail=str(data.get("detail", "")),
                   field=data.get("field"), allowed=data.get("allowed"), partial=data.get("partial"))


class JointdError(Exception):
    """Anything the client raises: a refusal of the daemon (`problem` is its
    answer, `status` its HTTP status), or `NotConnected`."""

    def __init__(self, problem: Problem):
        super().__init__(f"{problem.status} {problem.title}: {problem.detail}")
        self.problem = problem
        self.status = problem.status
        self.type = problem.type
        self.detail = problem.detail
        self.field = problem.field


class Invalid(JointdError):
    """400: the request was malformed (bad JSON, a missing or unknown field)."""


class Unauthorized(JointdError):
    """401: a token is required (`JOINTD_TOKEN`, or `token=`) or was wrong."""


class NotFound(JointdError):
    """404: unknown bus, device, hand, pose, move or recording."""


class Conflict(JointdError):
    """409: the joint's state does not allow it (e.g. not enabled, e-stopped)."""


class Unprocessable(Invalid):
    """422: a value out of range or outside a soft limit (`field` names it)."""


class TooMany(JointdError):
    """429: too many clients or requests at once."""


class Unavailable(JointdError):
    """503: the bus is down (or not every bus is up)."""


class Timeout(JointdError):
    """504, or a wait of the client that ran out (`wait=True`)."""


class NotConnected(JointdError):
    """The daemon could not be reached (not running, wrong `JOINTD_URL`)."""

    def __init__(self, url: str, reason: str):
        super().__init__(Problem(type="urn:jointd:client:not-connected", title="Not connected",
                                 status=0, detail=f"{url}: {reason}"))
        self.url = url


_BY_STATUS: Dict[int, Type[JointdError]] = {
    400: Invalid, 401: Unauthorized, 404: NotFound, 409: Conflict, 422: Unprocessable,
    429: TooMany, 503: Unavailable, 504: Timeout,
}

# The WebSocket's error codes (docs/websocket.md) and the HTTP status each
# stands for, so both sides raise the same classes.
WS_STATUS: Dict[str, int] = {
    "bad_json": 400, "bad_message": 400, "unknown_bus": 404, "unknown_device": 404,
    "out_of_range": 422, "out_of_limit": 422, "wrong_state": 409, "too_many": 429,
    "bus_error": 503,
}


def error_for(problem: Problem) -> JointdError:
    """The exception for a problem document, by its status."""
    return _BY_STATUS.get(problem.status, JointdError)(problem)


def ws_error(msg: Mapping[str, Any]) -> JointdError:
    """The exception for a WebSocket `error` message, by its code."""
    code = str(msg.get("code"))
    return error_for(Problem(type=f"urn:jointd:ws:{code}", title=code,
                             status=WS_STATUS.get(code, 0), detail=str(msg.get("message")),
                             field=msg.get("field")))
