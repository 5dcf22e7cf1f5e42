"""Python client of jointd: REST (`Jointd`) and WebSocket streams."""

from .client import Jointd
from .errors import Conflict, JointdError, NotFound, Problem, Unavailable, Unprocessable
from .models import ActionDone, Bus, Device, TargetAck
from .stream import SetpointStream, Telemetry

__all__ = [
    "Jointd", "JointdError", "NotFound", "Conflict", "Unprocessable", "Unavailable", "Problem",
    "Bus", "Device", "ActionDone", "TargetAck", "SetpointStream", "Telemetry",
]
