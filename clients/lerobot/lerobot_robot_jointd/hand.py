"""A hand on a daemon, over REST: its joints by name, enabling and
disabling them, and its calibration as LeRobot's calibration file holds it."""

from __future__ import annotations

from collections import defaultdict
from typing import Dict, List, Optional, Sequence, Tuple

from lerobot.motors import MotorCalibration
from lerobot.utils.errors import DeviceNotConnectedError

from jointd_client import Jointd
from jointd_client.errors import JointdError, NotConnected

# (joint name, bus, device id), in the hand's order.
Joint = Tuple[str, str, int]

# The protocol's angle range, degrees: a joint without a calibrated range.
PROTOCOL_RANGE_DEG = 255.0
# LeRobot's calibration file holds integers: angles in it are centidegrees.
CENTI = 100


class Hand:
    """Hand `name` of the daemon at `url`; `only` keeps some of its joints."""

    def __init__(self, url: str, token: Optional[str], name: str, only: Optional[Sequence[str]]):
        self.client = Jointd(url, token, timeout=5.0)
        self.name = name
        self._only = list(only) if only else None
        self._joints: Optional[List[Joint]] = None

    @property
    def joints(self) -> List[Joint]:
        """Its joints, asked of the daemon once (LeRobot reads the features
        before it connects)."""
        if self._joints is None:
            self._joints = self._describe()
        return self._joints

    def _describe(self) -> List[Joint]:
        try:
            hands = self.client.hands()["hands"]
        except NotConnected as e:
            raise DeviceNotConnectedError(
                f"jointd is not reachable at {self.client.url} ({e.detail}): start it "
                "(`jointd --sim 6 --config hand.toml`) or set --robot.url / JOINTD_URL") from None
        except JointdError as e:
            raise DeviceNotConnectedError(f"jointd at {self.client.url} refused: {e}") from None
        view = next((h for h in hands if h["name"] == self.name), None)
        if view is None:
            known = ", ".join(h["name"] for h in hands) or "none (add a [[hand]] to its config)"
            raise DeviceNotConnectedError(
                f"jointd at {self.client.url} has no hand `{self.name}`; its hands: {known}")
        joints = [(j["name"], j["bus"], int(j["id"])) for j in view["joints"]]
        if self._only is not None:
            names = {n for n, _, _ in joints}
            unknown = [n for n in self._only if n not in names]
            if unknown:
                raise ValueError(f"hand `{self.name}` has no joint {unknown}; its joints: {sorted(names)}")
            joints = [j for j in joints if j[0] in self._only]
        return joints

    def by_bus(self) -> Dict[str, List[int]]:
        out: Dict[str, List[int]] = defaultdict(list)
        for _, bus, i in self.joints:
            out[bus].append(i)
        return dict(out)

    def enable(self, timeout: float) -> None:
        """Enables its joints and returns once each runs (aligned)."""
        for bus, ids in self.by_bus().items():
            self.client.enable_all(bus, ids, wait=True, timeout=timeout)

    def disable(self) -> None:
        for bus, ids in self.by_bus().items():
            self.client.disable_all(bus, ids)

    def calibration(self) -> Dict[str, MotorCalibration]:
        """The daemon's calibration of each joint (offset, flip, range) as
        LeRobot keeps one: angles in centidegrees, `drive_mode` 1 when the
        joint is flipped, the protocol's ±255° where no range is set."""
        view = self.client.hand_calibration(self.name)
        wanted = {n for n, _, _ in self.joints}
        out: Dict[str, MotorCalibration] = {}
        for j in view["joints"]:
            if j["joint"] not in wanted:
                continue
            c = j["calibration"]
            low, high = c.get("range_deg") or (-PROTOCOL_RANGE_DEG, PROTOCOL_RANGE_DEG)
            out[j["joint"]] = MotorCalibration(
                id=int(c["id"]), drive_mode=1 if c.get("flip") else 0,
                homing_offset=round(float(c.get("offset_deg", 0.0)) * CENTI),
                range_min=round(float(low) * CENTI), range_max=round(float(high) * CENTI))
        return out

    def uncalibrated_ranges(self) -> List[str]:
        """Joints whose range the daemon does not know (no soft limits to clip to)."""
        view = self.client.hand_calibration(self.name)
        wanted = {n for n, _, _ in self.joints}
        return [j["joint"] for j in view["joints"]
                if j["joint"] in wanted and not j["calibration"].get("range_deg")]

    def limits(self) -> Dict[str, Tuple[float, float]]:
        """Each joint's soft limits in its calibrated frame, degrees (the
        daemon refuses a target beyond them)."""
        out: Dict[str, Tuple[float, float]] = {}
        for name, bus, i in self.joints:
            lim = self.client.device(bus, i)["limits"]
            out[name] = (float(lim["min_deg"]), float(lim["max_deg"]))
        return out
