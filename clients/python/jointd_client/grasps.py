"""Grasping: the four grasp calls (`GraspCalls`, part of `Jointd`) and the
`Grasp` handle they return. A thin adapter over the daemon's grasp routine
(docs/grasping.md): the daemon closes, detects contact, holds and restores
the current limits; the handle only reads and asks.
"""

import time
import urllib.parse
from typing import Any, Dict, List, Literal, Mapping, Optional, Sequence, Union, cast

from . import schema
from ._ops import operation
from .errors import NotFound, Problem, Timeout
from .moves import POLL_S, JobCalls, _Job

#: A finger that no longer closes: it holds, found nothing, lost its object,
#: or its part ended.
SETTLED: frozenset[str] = frozenset(
    {"holding", "no_contact", "lost", "released", "stopped", "aborted", "failed"})

#: Ending a grasp waits for its fingers (the daemon answers within 20 s).
END_TIMEOUT_S = 30.0

WaitUntil = Literal["settled", "done"]


class GraspCalls:
    """The grasp operations; `Jointd` has them (it provides `request`)."""

    def request(self, method: str, path: str, body: Any = None,
                timeout: Optional[float] = None) -> Any:
        raise NotImplementedError

    @operation("start_grasp")
    def grasp(self, hand: str, speed_dps: float, hold_current_a: float,
              contact_threshold_a: Optional[float] = None,
              joints: Optional[Sequence[Union[str, Mapping[str, Any]]]] = None,
              wait: bool = False, timeout: Optional[float] = None) -> "Grasp":
        """Close `hand`'s fingers at `speed_dps` (°/s) until each feels contact,
        then hold with `hold_current_a` (A of q current); a `Grasp` handle.
        `joints`: joint names, or `{"joint": "index", "close_to_deg": 80}`
        (default: every joint of the hand). With `wait`, returns once every
        finger settled (`Grasp.wait()`)."""
        body: Dict[str, Any] = {"speed_dps": speed_dps, "hold_current_a": hold_current_a}
        if contact_threshold_a is not None:
            body["contact_threshold_a"] = contact_threshold_a
        if joints is not None:
            body["joints"] = [{"joint": j} if isinstance(j, str) else dict(j) for j in joints]
        path = f"/api/v1/hands/{urllib.parse.quote(hand, safe='')}/grasp"
        g = Grasp(cast(JobCalls, self), cast(schema.GraspView, self.request("POST", path, body)))
        if wait:
            g.wait(timeout=timeout)
        return g

    @operation("get_grasp")
    def get_grasp(self, grasp_id: int) -> schema.GraspView:
        return cast(schema.GraspView, self.request("GET", f"/api/v1/grasps/{int(grasp_id)}"))

    @operation("release_grasp")
    def release_grasp(self, grasp_id: int, pose: Optional[str] = None,
                      open_deg: Optional[float] = None,
                      speed_dps: Optional[float] = None) -> schema.GraspView:
        """Open every finger still in the grasp (to the hand's `pose`, by
        `open_deg` from where it is, or back to where it started) and restore
        the limits; answers once every finger ended."""
        body = {k: v for k, v in
                {"pose": pose, "open_deg": open_deg, "speed_dps": speed_dps}.items()
                if v is not None}
        return cast(schema.GraspView,
                    self.request("POST", f"/api/v1/grasps/{int(grasp_id)}/release", body,
                                 timeout=END_TIMEOUT_S))

    @operation("stop_grasp")
    def stop_grasp(self, grasp_id: int) -> schema.GraspView:
        """Hold every finger where it is and restore the limits; a grasp that
        already ended answers its final state."""
        return cast(schema.GraspView,
                    self.request("POST", f"/api/v1/grasps/{int(grasp_id)}/stop",
                                 timeout=END_TIMEOUT_S))


class Grasp(_Job[schema.GraspView]):
    """A grasp running in the daemon (`Jointd.grasp`)."""

    @property
    def state(self) -> str:
        """`running` while any finger is under the grasp's control, then
        `done` (each finger's `state` says how), as last seen."""
        return self.view["state"]

    @property
    def fingers(self) -> List[schema.FingerGrasp]:
        """Each finger as last seen: `state`, `contact`, `contact_deg`,
        `q_current_a`, `current_limit_restored`, `reason`."""
        return self.view["fingers"]

    def finger(self, joint: str) -> schema.FingerGrasp:
        """Finger `joint` (its name in the hand), as last seen."""
        for f in self.view["fingers"]:
            if f["joint"] == joint:
                return f
        names = ", ".join(f["joint"] for f in self.view["fingers"])
        raise NotFound(Problem(type="urn:jointd:client:unknown-finger", title="Unknown finger",
                               status=0, detail=f"{self!r} has no finger `{joint}` ({names})"))

    def _fetch(self) -> schema.GraspView:
        return self._client.get_grasp(self.id)

    def settled(self) -> bool:
        """As last seen: the grasp ended, or no finger still starts or closes."""
        return self.state != "running" or all(f["state"] in SETTLED for f in self.fingers)

    def wait(self, timeout: Optional[float] = None,
             until: WaitUntil = "settled") -> schema.GraspView:
        """Until every finger holds, found nothing at its limit or lost its
        object, or the grasp ended (`until="settled"`); or until it ended
        (`until="done"`). `Timeout` after `timeout` s; the view then."""
        if until == "done":
            return super().wait(timeout)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            self.refresh()
            if self.settled():
                return self.view
            if deadline is not None and time.monotonic() >= deadline:
                raise Timeout(Problem(type="urn:jointd:client:timeout", title="Timeout", status=0,
                                      detail=f"{self!r}: fingers still closing after {timeout} s"))
            time.sleep(POLL_S)

    def release(self, pose: Optional[str] = None, open_deg: Optional[float] = None,
                speed_dps: Optional[float] = None) -> schema.GraspView:
        """Let go (see `Jointd.release_grasp`); the grasp as it ended."""
        self.view = self._client.release_grasp(self.id, pose=pose, open_deg=open_deg,
                                               speed_dps=speed_dps)
        return self.view

    def stop(self) -> schema.GraspView:
        """Hold every finger where it is and end the grasp; as it ended."""
        self.view = self._client.stop_grasp(self.id)
        return self.view
