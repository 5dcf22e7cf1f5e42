"""Handles of jobs that run in the daemon: a `Move` (a move or a go to a
pose) and a `Homing`. Each knows its last view, refreshes it on request,
and waits for its end by polling (the daemon keeps a finished job's view).
"""

import time
from typing import TYPE_CHECKING, Callable, Optional, TypeVar

from . import schema
from .errors import Problem, Timeout

if TYPE_CHECKING:
    from .client import Jointd

V = TypeVar("V")

POLL_S = 0.02


def _wait(fetch: Callable[[], V], running: Callable[[V], bool], what: str,
          timeout: Optional[float]) -> V:
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        view = fetch()
        if not running(view):
            return view
        if deadline is not None and time.monotonic() >= deadline:
            raise Timeout(Problem(type="urn:jointd:client:timeout", title="Timeout", status=0,
                                  detail=f"{what} still running after {timeout} s"))
        time.sleep(POLL_S)


class Move:
    """A move running in the daemon (`Jointd.move`, `Jointd.go_to_pose`)."""

    def __init__(self, client: "Jointd", view: schema.MoveView):
        self._client = client
        self.view = view

    @property
    def id(self) -> int:
        return self.view["id"]

    @property
    def state(self) -> schema.MoveState:
        """`running`, `done`, `stopped`, `aborted` or `stalled`, as last seen
        (`refresh()` asks again)."""
        return self.view["state"]

    def refresh(self) -> schema.MoveView:
        self.view = self._client.get_move(self.id)
        return self.view

    def wait(self, timeout: Optional[float] = None) -> schema.MoveView:
        """Until the move ended (`Timeout` after `timeout` s); its final view."""
        self.view = _wait(self.refresh, lambda v: v["state"] == "running", f"move {self.id}",
                          timeout)
        return self.view

    def stop(self) -> schema.MoveView:
        """Stop it where the joints are (they hold there, enabled)."""
        self.view = self._client.stop_move(self.id)
        return self.view

    def __repr__(self) -> str:
        return f"Move(id={self.id}, state={self.state!r})"


class Homing:
    """A homing job running in the daemon (`Jointd.home`)."""

    def __init__(self, client: "Jointd", view: schema.HomingView):
        self._client = client
        self.view = view

    @property
    def id(self) -> int:
        return self.view["id"]

    @property
    def state(self) -> str:
        """`running` until every joint ended, then `done` (each joint's own
        state says how), as last seen."""
        return self.view["state"]

    def refresh(self) -> schema.HomingView:
        self.view = self._client.get_homing(self.id)
        return self.view

    def wait(self, timeout: Optional[float] = None) -> schema.HomingView:
        """Until every joint ended (`Timeout` after `timeout` s); the final view."""
        self.view = _wait(self.refresh, lambda v: v["state"] == "running", f"homing {self.id}",
                          timeout)
        return self.view

    def __repr__(self) -> str:
        return f"Homing(id={self.id}, state={self.state!r})"
