"""A hand on a jointd daemon for LeRobot: the robot `jointd` (a follower)
and the teleoperator `jointd_leader`. LeRobot imports this package by its
distribution name (`lerobot_robot_*`), which registers both."""

from .config_jointd import JointdConfig, JointdLeaderConfig
from .leader import JointdLeader
from .robot import Jointd
from .link import HandStopped, Refused

__all__ = ["Jointd", "JointdConfig", "JointdLeader", "JointdLeaderConfig", "HandStopped", "Refused"]
