"""Handles of jobs that run in the daemon: a `Move` (a move or a go to a
pose) and a `Homing` (and the base of `grasps.Grasp`). Each knows its last view, refreshes it on request,
and waits for its end by polling (the daemon keeps a finished job's view).
"""

import time
from typing import Generic, Optional, Protocol, TypeVar

from . import schema
from .errors import Problem, Timeout


class JobCalls(Protocol):
    """The calls a job handle makes (`Jointd` has them)."""

    def get_move(self, move_id: int) -> schema.MoveView: ...

    def stop_move(self, move_id: int) -> schema.MoveView: ...

    def get_homing(self, homing_id: int) -> schema.HomingView: ...

    def get_grasp(self, grasp_id: int) -> schema.GraspView: ...

    def release_grasp(self, grasp_id: int, pose: Optional[str] = None,
                      open_deg: Optional[float] = None,
                      speed_dps: Optional[float] = None) -> schema.GraspView: ...

    def stop_grasp(self, grasp_id: int) -> schema.GraspView: ...

POLL_S = 0.02


J = TypeVar("J", schema.MoveView, schema.HomingView, schema.GraspView)


class _Job(Generic[J]):
    """A job's last view, refreshed on request, waited for by polling."""

    def __init__(self, client: JobCalls, view: J):
        self._client = client
        self.view: J = view

    @property
    def id(self) -> int:
        return self.view["id"]

    def _fetch(self) -> J:
        raise NotImplementedError

    def refresh(self) -> J:
        self.view = self._fetch()
        return self.view

    def wait(self, timeout: Optional[float] = None) -> J:
        """Until it ended (`Timeout` after `timeout` s); its final view."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.refresh()["state"] == "running":
            if deadline is not None and time.monotonic() >= deadline:
                raise Timeout(Problem(type="urn:jointd:client:timeout", title="Timeout", status=0,
                                      detail=f"{self!r} still running after {timeout} s"))
            time.sleep(POLL_S)
        return self.view

    def __repr__(self) -> str:
        return f"{type(self).__name__}(id={self.id}, state={self.view['state']!r})"


class Move(_Job[schema.MoveView]):
    """A move running in the daemon (`Jointd.move`, `Jointd.go_to_pose`)."""

    @property
    def state(self) -> schema.MoveState:
        """`running`, `done`, `stopped`, `aborted` or `stalled`, as last seen
        (`refresh()` asks again)."""
        return self.view["state"]

    def _fetch(self) -> schema.MoveView:
        return self._client.get_move(self.id)

    def stop(self) -> schema.MoveView:
        """Stop it where the joints are (they hold there, enabled)."""
        self.view = self._client.stop_move(self.id)
        return self.view


class Homing(_Job[schema.HomingView]):
    """A homing job running in the daemon (`Jointd.home`)."""

    @property
    def state(self) -> str:
        """`running` until every joint ended, then `done` (each joint's own
        state says how), as last seen."""
        return self.view["state"]

    def _fetch(self) -> schema.HomingView:
        return self._client.get_homing(self.id)
