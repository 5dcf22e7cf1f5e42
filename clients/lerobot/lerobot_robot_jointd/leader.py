"""`jointd_leader`: a leader hand on a jointd daemon as a LeRobot
teleoperator (a second hand, or a glove built from the same modules with
its motors off, moved by a person). It only reads: it never enables,
moves or configures the leader's joints."""

from __future__ import annotations

import logging
import time
from functools import cached_property
from typing import Any, Dict, List, Optional

from lerobot.processor import RobotAction
from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError

from .config_jointd import JointdLeaderConfig
from .hand import Hand
from .link import HandLink, LinkError, present

logger = logging.getLogger(__name__)

CLIENT_NAME = "lerobot-jointd-leader"


class JointdLeader(Teleoperator):
    """A leader hand of a jointd daemon (`--teleop.type=jointd_leader --teleop.hand=NAME`)."""

    config_class = JointdLeaderConfig
    name = "jointd_leader"

    def __init__(self, config: JointdLeaderConfig):
        super().__init__(config)
        self.config = config
        self.hand = Hand(config.url, config.token, config.hand, config.joints)
        self._link: Optional[HandLink] = None

    def _follower_name(self, leader_name: str) -> str:
        return self.config.joint_map.get(leader_name, leader_name)

    @property
    def joint_names(self) -> List[str]:
        return [self._follower_name(n) for n, _, _ in self.hand.joints]

    @cached_property
    def action_features(self) -> Dict[str, type]:
        return {f"{n}.pos": float for n in self.joint_names}

    @cached_property
    def feedback_features(self) -> Dict[str, type]:
        return {}

    @property
    def is_connected(self) -> bool:
        return self._link is not None and self._link.is_open

    def connect(self, calibrate: bool = True) -> None:
        if self._link is not None:
            raise DeviceAlreadyConnectedError(f"{self} is already connected")
        unknown = [n for n in self.config.joint_map if n not in {j for j, _, _ in self.hand.joints}]
        if unknown:
            raise ValueError(f"joint_map names {unknown}, not joints of leader hand `{self.config.hand}`")
        link = HandLink(self.hand.client.ws_url(), self.config.token,
                        [(bus, i) for _, bus, i in self.hand.joints], self.config.telemetry_hz,
                        CLIENT_NAME)
        try:
            link.open()
            link.wait_for_samples(timeout=5.0)
        except LinkError as e:
            link.close()
            raise DeviceNotConnectedError(str(e)) from None
        self._link = link
        if not self.is_calibrated and calibrate:
            self.calibrate()
        logger.info("%s connected: leader hand %s", self, self.config.hand)

    @property
    def is_calibrated(self) -> bool:
        return bool(self.calibration) and self.calibration == self.hand.calibration()

    def calibrate(self) -> None:
        """Writes the daemon's calibration of the leader to LeRobot's file."""
        self.calibration = self.hand.calibration()
        self._save_calibration()

    def configure(self) -> None:
        """Nothing to write: a leader is only read."""

    def get_action(self) -> RobotAction:
        if self._link is None:
            raise DeviceNotConnectedError(f"{self} is not connected; run `.connect()` first")
        try:
            joints = present(self._link.latest(), self.hand.joints, time.monotonic(),
                          self.config.stale_after_ms / 1e3, f"leader hand {self.config.hand}")
        except LinkError as e:
            raise DeviceNotConnectedError(str(e)) from None
        action: Dict[str, Any] = {f"{self._follower_name(name)}.pos": float(f["angle_deg"])
                                  for name, f in joints.items()}
        return action

    def send_feedback(self, feedback: Dict[str, Any]) -> None:
        """A leader of these modules has nothing to show: no-op."""

    def disconnect(self) -> None:
        if self._link is None:
            raise DeviceNotConnectedError(f"{self} is not connected")
        self._link.close()
        self._link = None
