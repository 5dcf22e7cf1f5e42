"""The LeRobot configurations of a hand on a jointd daemon: `jointd` (a
follower robot) and `jointd_leader` (a leader teleoperator). Both register
themselves when LeRobot imports this package, which it does for every
installed distribution named `lerobot_robot_*`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from lerobot.cameras import CameraConfig
from lerobot.robots.config import RobotConfig
from lerobot.teleoperators.config import TeleoperatorConfig

DEFAULT_URL = "http://127.0.0.1:8080"


def _env_url() -> str:
    return os.environ.get("JOINTD_URL") or DEFAULT_URL


def _env_token() -> str | None:
    return os.environ.get("JOINTD_TOKEN") or None


@RobotConfig.register_subclass("jointd")
@dataclass
class JointdConfig(RobotConfig):
    # The daemon (default $JOINTD_URL, else http://127.0.0.1:8080) and its
    # bearer token (default $JOINTD_TOKEN).
    url: str = field(default_factory=_env_url)
    token: str | None = field(default_factory=_env_token)
    # A hand of the daemon's config (`[[hand]]`, GET /api/v1/hands).
    hand: str = ""
    # Only these of the hand's joints (by name); all of them by default.
    joints: list[str] | None = None
    # The most a joint's target may be from where it is, degrees (one value
    # for every joint, or by joint name), as LeRobot's own robots clip.
    max_relative_target: float | dict[str, float] | None = None
    # Disable the hand's joints on disconnect(); otherwise they are left as
    # the daemon keeps them (holding their last target).
    disable_on_disconnect: bool = False
    # The observation also carries `<joint>.vel` (°/s) and `<joint>.current` (A).
    observe_velocity: bool = False
    observe_current: bool = False
    # Telemetry subscription rate, Hz (the daemon polls each joint faster).
    telemetry_hz: float = 200.0
    # The daemon's teleoperation watchdog: without setpoints for this long
    # (a policy process that died or hung), `hold` freezes each joint where
    # it is, `disable` disables them.
    hold_timeout_ms: int = 500
    watchdog_policy: str = "hold"
    # Speed limit of the targets, output °/s (the daemon caps it by the
    # joint's soft limit).
    speed_dps: float = 360.0
    # How long connect() waits for the joints to align after enabling, s.
    enable_timeout_s: float = 10.0
    # A joint sample older than this (the daemon's age of it plus the time
    # since this process took it) is no observation: get_observation and
    # send_action raise instead of passing an old angle off as new.
    stale_after_ms: float = 1000.0
    cameras: dict[str, CameraConfig] = field(default_factory=dict)
    # Ask the daemon to say when each action is on the wire (an ack per
    # action, read in the background; the robot's `latencies()` gives them).
    measure_latency: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.hand:
            raise ValueError("--robot.hand is required: a hand of the daemon (GET /api/v1/hands)")
        if self.watchdog_policy not in ("hold", "disable"):
            raise ValueError(f"watchdog_policy must be `hold` or `disable`, not `{self.watchdog_policy}`")


@TeleoperatorConfig.register_subclass("jointd_leader")
@dataclass
class JointdLeaderConfig(TeleoperatorConfig):
    url: str = field(default_factory=_env_url)
    token: str | None = field(default_factory=_env_token)
    # The leader hand on its daemon (a second hand, or a glove of the same
    # modules with its motors off).
    hand: str = ""
    # Leader joint name -> follower joint name, where they differ.
    joint_map: dict[str, str] = field(default_factory=dict)
    # Only these leader joints (by name); all of them by default.
    joints: list[str] | None = None
    telemetry_hz: float = 200.0
    # As the robot's: an older leader sample is no action.
    stale_after_ms: float = 1000.0

    def __post_init__(self) -> None:
        if not self.hand:
            raise ValueError("--teleop.hand is required: a hand of the leader's daemon (GET /api/v1/hands)")
