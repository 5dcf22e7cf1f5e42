"""Typed views of the daemon's answers. Each mirrors a schema of
openapi/openapi.json (named in `SCHEMA`); tests/test_models.py checks every
field against the document, so a renamed field fails there, not in a user's
script. Fields the client does not model stay reachable in `raw`."""

from dataclasses import dataclass, field, fields
from typing import Any, Dict, List, Mapping, Optional, Type, TypeVar

M = TypeVar("M", bound="_FromJson")


class _FromJson:
    """`Model.from_json(answer)`: the modelled fields, the whole answer in `raw`."""

    @classmethod
    def from_json(cls: Type[M], data: Mapping[str, Any]) -> M:
        names = {f.name for f in fields(cls)} - {"raw"}  # type: ignore[arg-type]
        # Every model is a dataclass with these fields and `raw`.
        return cls(**{n: data.get(n) for n in names}, raw=dict(data))  # type: ignore[call-arg]


@dataclass(frozen=True)
class Bus(_FromJson):
    SCHEMA = "BusView"
    name: str
    path: str
    baud: int
    link: str
    devices_known: int
    devices_online: int
    queue_depth: int
    raw: Dict[str, Any] = field(repr=False, compare=False)


@dataclass(frozen=True)
class Device(_FromJson):
    SCHEMA = "DeviceSummary"
    id: int
    name: Optional[str]
    online: bool
    state: Optional[str]
    angle_deg: Optional[float]
    speed_dps: Optional[float]
    q_current_a: Optional[float]
    temp_c: Optional[float]
    vbus_v: Optional[float]
    target_known: bool
    raw: Dict[str, Any] = field(repr=False, compare=False)


@dataclass(frozen=True)
class ActionDone(_FromJson):
    SCHEMA = "ActionDone"
    bus: str
    action: str
    ids: Optional[List[int]]
    value: Optional[Any]
    raw: Dict[str, Any] = field(repr=False, compare=False)


@dataclass(frozen=True)
class TargetAck(_FromJson):
    SCHEMA = "TargetAck"
    bus: str
    seq: int
    on_wire: bool
    targets: List[Dict[str, Any]]
    raw: Dict[str, Any] = field(repr=False, compare=False)


MODELS: List[Type[_FromJson]] = [Bus, Device, ActionDone, TargetAck]
