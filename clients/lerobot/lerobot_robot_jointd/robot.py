"""`jointd`: a follower hand on a jointd daemon as a LeRobot robot.

Observations come from a WebSocket telemetry subscription kept up to date
in the background; actions are streamed as setpoints on the same socket,
under the daemon's teleoperation watchdog. Angles are degrees in each
joint's calibrated frame, keyed `<joint name>.pos` as the hand names them.
"""

from __future__ import annotations

import logging
import math
import time
from functools import cached_property
from typing import Any, Dict, List, Optional, Tuple

from lerobot.cameras.utils import make_cameras_from_configs
from lerobot.processor import RobotAction, RobotObservation
from lerobot.robots.robot import Robot
from lerobot.robots.utils import ensure_safe_goal_position
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError

from jointd_client.errors import JointdError

from .config_jointd import JointdConfig
from .hand import Hand
from .link import HandLink, HandStopped, LinkError, Refused, present

logger = logging.getLogger(__name__)

# The name this plugin gives itself on the daemon's WebSocket (the
# dashboard shows it beside the joints it drives).
CLIENT_NAME = "lerobot-jointd"


class Jointd(Robot):
    """A hand of a jointd daemon (`--robot.type=jointd --robot.hand=NAME`)."""

    config_class = JointdConfig
    name = "jointd"

    def __init__(self, config: JointdConfig):
        super().__init__(config)
        self.config = config
        self.hand = Hand(config.url, config.token, config.hand, config.joints)
        self.cameras = make_cameras_from_configs(config.cameras)
        self._link: Optional[HandLink] = None
        self._limits: Dict[str, Tuple[float, float]] = {}
        self._clipped: set[str] = set()
        self.sent_actions = 0

    # ------------------------------------------------------------ features

    @property
    def joint_names(self) -> List[str]:
        return [n for n, _, _ in self.hand.joints]

    @cached_property
    def _joints_ft(self) -> Dict[str, type]:
        ft: Dict[str, type] = {}
        for n in self.joint_names:
            ft[f"{n}.pos"] = float
            if self.config.observe_velocity:
                ft[f"{n}.vel"] = float
            if self.config.observe_current:
                ft[f"{n}.current"] = float
        return ft

    @cached_property
    def observation_features(self) -> Dict[str, Any]:
        cams = {name: (c.height, c.width, 3) for name, c in self.config.cameras.items()}
        return {**self._joints_ft, **cams}

    @cached_property
    def action_features(self) -> Dict[str, type]:
        return {f"{n}.pos": float for n in self.joint_names}

    # ---------------------------------------------------------- connection

    @property
    def is_connected(self) -> bool:
        return (self._link is not None and self._link.is_open
                and all(c.is_connected for c in self.cameras.values()))

    def connect(self, calibrate: bool = True) -> None:
        """Enables the hand's joints, waits until they run, and begins the
        stream to each. The only place this plugin enables anything."""
        if self._link is not None:
            raise DeviceAlreadyConnectedError(f"{self} is already connected")
        joints = self.hand.joints  # a clear error when the daemon or the hand is not there
        self._check_max_relative()
        if not self.is_calibrated and calibrate:
            self.calibrate()
        try:
            self._limits = self.hand.limits()
        except JointdError as e:
            raise DeviceNotConnectedError(f"could not read hand `{self.config.hand}`: {e}") from None
        self._clipped = set()
        # The link is open (and hears e-stops) before anything is enabled.
        link = HandLink(self.hand.client.ws_url(), self.config.token,
                        [(bus, i) for _, bus, i in joints], self.config.telemetry_hz, CLIENT_NAME)
        try:
            link.open()
            link.arm_watchdog(self.config.hold_timeout_ms, self.config.watchdog_policy)
        except LinkError as e:
            link.close()
            raise DeviceNotConnectedError(str(e)) from None
        enabled = False
        try:
            self.hand.enable(self.config.enable_timeout_s)
            enabled = True
            link.wait_for_samples(timeout=5.0, ok=lambda f: f.get("state") == "run")
            self._begin_streams(link)
            if link.stopping_events:
                raise LinkError(f"the hand was stopped while connecting: {link.stopping_events[0]}")
            for cam in self.cameras.values():
                cam.connect()
        except Exception as e:
            # Enabled here and not streamed to: left enabled, nobody would
            # hold it under a watchdog.
            link.close()
            if enabled:
                try:
                    self.hand.disable()
                except JointdError as d:
                    logger.error("could not disable hand %s after a failed connect: %s", self.config.hand, d)
            if isinstance(e, (LinkError, JointdError)):
                raise DeviceNotConnectedError(f"could not connect hand `{self.config.hand}`: {e}") from None
            raise
        self._link = link
        logger.info("%s connected: hand %s, joints %s", self, self.config.hand, self.joint_names)

    def _check_max_relative(self) -> None:
        cap = self.config.max_relative_target
        if isinstance(cap, dict):
            missing = [n for n in self.joint_names if n not in cap]
            unknown = [n for n in cap if n not in self.joint_names]
            if missing or unknown:
                raise ValueError(f"max_relative_target names joints {sorted(cap)}: "
                                 f"missing {missing}, not of hand `{self.config.hand}` {unknown}")

    def _begin_streams(self, link: HandLink) -> None:
        """Begins the stream to every joint now, under the enable just
        made, with the joints' own measured angles as targets (they stay
        where they stand). Any e-stop, disable, reset or fault after this
        ends the stream, and `send_action` raises from then on, even
        before the first action: a hand stopped and enabled again by
        someone else in between is never driven by this connection. (An
        e-stop between the enable and this is heard as an event, and fails
        the connect.)"""
        latest = link.latest()
        holds = []
        for name, bus, i in self.hand.joints:
            angle = latest[(bus, i)].fields.get("angle_deg")
            if angle is None:
                raise LinkError(f"joint {name} ({bus}/{i}) reports no angle (offline?)")
            holds.append({"bus": bus, "id": i, "position_deg": angle, "speed_dps": self.config.speed_dps})
        seq = link.send(holds, ack=True)
        assert seq is not None
        link.wait_ack(seq, timeout=5.0)

    def disconnect(self) -> None:
        if self._link is None:
            raise DeviceNotConnectedError(f"{self} is not connected")
        self._link.close()
        self._link = None
        for cam in self.cameras.values():
            cam.disconnect()
        if self.config.disable_on_disconnect:
            self.hand.disable()
        logger.info("%s disconnected", self)

    # --------------------------------------------------------- calibration

    @property
    def is_calibrated(self) -> bool:
        """LeRobot's calibration file says what the daemon's calibration is."""
        return bool(self.calibration) and self.calibration == self.hand.calibration()

    def calibrate(self) -> None:
        """The daemon holds each joint's calibration (offset, flip, range:
        homing or PUT …/calibration set it); this writes it to LeRobot's
        calibration file so both say the same."""
        self.calibration = self.hand.calibration()
        self._save_calibration()
        loose = self.hand.uncalibrated_ranges()
        if loose:
            logger.warning("hand %s: no range for %s (home them, or set soft limits); "
                           "their targets are limited only by the protocol's ±255°",
                           self.config.hand, loose)
        logger.info("calibration of %s written to %s", self.config.hand, self.calibration_fpath)

    def configure(self) -> None:
        """Nothing to write: the daemon's config is the joints' configuration."""

    # ----------------------------------------------------------- the loop

    def _require_link(self) -> HandLink:
        if self._link is None:
            raise DeviceNotConnectedError(f"{self} is not connected; run `.connect()` first")
        return self._link

    def _present(self) -> Dict[str, Dict[str, Any]]:
        """Each joint's newest telemetry, fresh and with an angle, else
        `DeviceNotConnectedError` saying which joint and why."""
        link = self._require_link()
        try:
            return present(link.latest(), self.hand.joints, time.monotonic(),
                           self.config.stale_after_ms / 1e3, f"hand {self.config.hand}")
        except LinkError as e:
            raise DeviceNotConnectedError(str(e)) from None

    def get_observation(self) -> RobotObservation:
        obs: Dict[str, Any] = {}
        for name, f in self._present().items():
            obs[f"{name}.pos"] = float(f["angle_deg"])
            if self.config.observe_velocity:
                obs[f"{name}.vel"] = float(f.get("speed_dps") or 0.0)
            if self.config.observe_current:
                obs[f"{name}.current"] = float(f.get("q_current_a") or 0.0)
        for key, cam in self.cameras.items():
            obs[key] = cam.async_read()
        return obs

    def send_action(self, action: RobotAction) -> RobotAction:
        """Streams `<joint>.pos` targets; returns what was sent (clipped by
        `max_relative_target` from where each joint is, and to its soft
        limits). Once the daemon said the hand was stopped (e-stop,
        disable, reset, fault) raises `HandStopped` and sends nothing; a
        joint offline or telemetry gone stale raises
        `DeviceNotConnectedError`; an earlier batch the daemon refused
        raises `Refused` once."""
        link = self._require_link()
        goal = {k.removesuffix(".pos"): float(v) for k, v in action.items() if k.endswith(".pos")}
        unknown = [n for n in goal if n not in self.joint_names]
        if unknown:
            raise ValueError(f"hand `{self.config.hand}` has no joint {unknown}")
        bad = [n for n, g in goal.items() if not math.isfinite(g)]
        if bad:
            raise ValueError(f"targets of {bad} are not finite numbers: {action}")
        link.check()
        measured = self._present()
        if self.config.max_relative_target is not None:
            goal = ensure_safe_goal_position(
                {n: (g, float(measured[n]["angle_deg"])) for n, g in goal.items()},
                self._max_relative(goal))
        goal = {n: self._within_limits(n, g) for n, g in goal.items()}
        where = {n: (bus, i) for n, bus, i in self.hand.joints}
        targets = [{"bus": where[n][0], "id": where[n][1], "position_deg": g,
                    "speed_dps": self.config.speed_dps} for n, g in goal.items()]
        try:
            link.send(targets, measure=self.config.measure_latency)
        except Refused as r:
            if r.code == "out_of_limit":
                # A soft limit changed since connect(): clip to the new ones from now on.
                self._limits = self.hand.limits()
                self._clipped = set()
            raise
        except HandStopped:
            raise
        except LinkError as e:
            raise DeviceNotConnectedError(str(e)) from None
        self.sent_actions += 1
        return {f"{n}.pos": g for n, g in goal.items()}

    def _within_limits(self, name: str, goal: float) -> float:
        """`goal` within the joint's soft limits (the daemon would refuse
        the whole batch), said once per joint and connection."""
        low, high = self._limits[name]
        clipped = min(max(goal, low), high)
        if clipped != goal and name not in self._clipped:
            self._clipped.add(name)
            logger.warning("%s: target %.1f° of %s is beyond its soft limits [%g, %g]: sent %.1f° "
                           "(said once per joint; the returned action says what was sent)",
                           self, goal, name, low, high, clipped)
        return clipped

    def _max_relative(self, goal: Dict[str, float]) -> float | Dict[str, float]:
        cap = self.config.max_relative_target
        if isinstance(cap, dict):
            return {n: float(cap[n]) for n in goal}
        return float(cap)  # type: ignore[arg-type]

    def latencies(self) -> List[Tuple[float, float]]:
        """With `measure_latency`: per acked action, (send_action -> ack
        received, ms; the daemon's accepted -> on the wire, ms)."""
        return list(self._link.latencies) if self._link is not None else []

    def observation_age_ms(self) -> float:
        """The oldest joint sample's age now, ms: the daemon's age of it when
        sent plus the time since this process took it."""
        link = self._require_link()
        now = time.monotonic()
        return max(s.age_ms + (now - s.taken_at) * 1e3 for s in link.latest().values())
