"""Python client of jointd: REST (`Jointd`) and WebSocket streams.

`Jointd()` reads `JOINTD_URL` and `JOINTD_TOKEN`; every error it raises is
a `JointdError`; the daemon's schemas are types in `jointd_client.schema`.
"""

from . import schema
from ._ops import operation
from .client import Jointd
from .errors import (Conflict, Invalid, JointdError, NotConnected, NotFound, Problem, Timeout,
                     TooMany, Unauthorized, Unavailable, Unprocessable)
from .models import ActionDone, Bus, Device, TargetAck
from .grasps import Grasp
from .moves import Homing, Move
from .stream import JointSample, SetpointStream, Telemetry

__all__ = [
    "Jointd", "operation", "schema",
    "JointdError", "NotConnected", "Invalid", "Unauthorized", "NotFound", "Conflict",
    "Unprocessable", "TooMany", "Unavailable", "Timeout", "Problem",
    "Bus", "Device", "ActionDone", "TargetAck", "Move", "Homing", "Grasp",
    "SetpointStream", "Telemetry", "JointSample",
]
