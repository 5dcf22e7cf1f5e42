"""Exceptions carrying the daemon's RFC 9457 problem document."""

from dataclasses import dataclass
from typing import Any, Optional


@dataclass(frozen=True)
class Problem:
    """The `Problem` schema of openapi/openapi.json."""

    SCHEMA = "Problem"
    type: str
    title: str
    status: int
    detail: str
    field: Optional[str] = None
    allowed: Optional[dict] = None
    partial: Optional[Any] = None

    @classmethod
    def from_json(cls, data: dict) -> "Problem":
        return cls(type=data.get("type", ""), title=data.get("title", ""),
                   status=int(data.get("status", 0)), detail=data.get("detail", ""),
                   field=data.get("field"), allowed=data.get("allowed"), partial=data.get("partial"))


class JointdError(Exception):
    """A request the daemon refused; `problem` is its answer."""

    def __init__(self, problem: Problem):
        super().__init__(f"{problem.status} {problem.title}: {problem.detail}")
        self.problem = problem
        self.status = problem.status
        self.type = problem.type
        self.detail = problem.detail
        self.field = problem.field


class NotFound(JointdError):
    """404: unknown bus or device."""


class Conflict(JointdError):
    """409: the device's state does not allow it (e.g. not enabled)."""


class Unprocessable(JointdError):
    """422: a value out of range or outside a soft limit (`field` names it)."""


class Unavailable(JointdError):
    """503: the bus is down (or not every bus is up)."""


_BY_STATUS = {404: NotFound, 409: Conflict, 422: Unprocessable, 503: Unavailable}


def error_for(problem: Problem) -> JointdError:
    return _BY_STATUS.get(problem.status, JointdError)(problem)
