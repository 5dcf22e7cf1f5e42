"""REST calls of jointd, one method each, with the standard library only."""

import json
import urllib.error
import urllib.parse
import urllib.request
from typing import Any, Iterable, List, Optional

from .errors import Problem, error_for
from .models import ActionDone, Bus, Device, TargetAck
from .stream import SetpointStream, telemetry


class Jointd:
    """A daemon at `url` (e.g. `http://127.0.0.1:8080`)."""

    def __init__(self, url: str = "http://127.0.0.1:8080", token: Optional[str] = None,
                 timeout: float = 10.0):
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout

    # ------------------------------------------------------------------ REST

    def request(self, method: str, path: str, body: Any = None) -> Any:
        """One call; the decoded JSON answer, or a `JointdError` with the problem."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, method=method, data=data)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as r:
                text = r.read()
        except urllib.error.HTTPError as e:
            text = e.read()
            try:
                problem = Problem.from_json(json.loads(text))
            except ValueError:
                problem = Problem(type="about:blank", title=e.reason or "HTTP error",
                                  status=e.code, detail=text.decode(errors="replace"))
            raise error_for(problem) from None
        return json.loads(text) if text else None

    def _bus(self, bus: str) -> str:
        return "/api/v1/buses/" + urllib.parse.quote(bus, safe="")

    def _dev(self, bus: str, dev_id: int) -> str:
        return f"{self._bus(bus)}/devices/{int(dev_id)}"

    def buses(self) -> List[Bus]:
        return [Bus.from_json(b) for b in self.request("GET", "/api/v1/buses")["buses"]]

    def bus(self, bus: str) -> Bus:
        return Bus.from_json(self.request("GET", self._bus(bus)))

    def devices(self, bus: str) -> List[Device]:
        return [Device.from_json(d) for d in self.request("GET", self._bus(bus) + "/devices")["devices"]]

    def device(self, bus: str, dev_id: int, fresh: bool = False) -> dict:
        """The full device view (INFO_01/INFO_02 decoded, raw bytes beside)."""
        return self.request("GET", self._dev(bus, dev_id) + ("?fresh=true" if fresh else ""))

    def enable(self, bus: str, dev_id: int) -> ActionDone:
        return ActionDone.from_json(self.request("POST", self._dev(bus, dev_id) + "/enable"))

    def disable(self, bus: str, dev_id: int) -> ActionDone:
        return ActionDone.from_json(self.request("POST", self._dev(bus, dev_id) + "/disable"))

    def enable_all(self, bus: str, ids: Optional[Iterable[int]] = None) -> ActionDone:
        body = {} if ids is None else {"ids": list(ids)}
        return ActionDone.from_json(self.request("POST", self._bus(bus) + "/control/enable", body))

    def disable_all(self, bus: str, ids: Optional[Iterable[int]] = None) -> ActionDone:
        body = {} if ids is None else {"ids": list(ids)}
        return ActionDone.from_json(self.request("POST", self._bus(bus) + "/control/disable", body))

    def target(self, bus: str, dev_id: int, position_deg: Optional[float] = None,
               speed_rpm: Optional[float] = None) -> TargetAck:
        body = {k: v for k, v in (("position_deg", position_deg), ("speed_rpm", speed_rpm)) if v is not None}
        return TargetAck.from_json(self.request("PUT", self._dev(bus, dev_id) + "/target", body))

    def set_mode(self, bus: str, dev_id: int, mode: str) -> ActionDone:
        return ActionDone.from_json(self.request("PUT", self._dev(bus, dev_id) + "/mode", {"mode": mode}))

    def config(self, bus: str, dev_id: int) -> dict:
        """Every parameter read from the device now: `{key: {value, raw, unit, index}}`."""
        return self.request("GET", self._dev(bus, dev_id) + "/config")

    def set_config(self, bus: str, dev_id: int, **params: float) -> dict:
        """Write any subset of parameters (RAM), each verified by read-back."""
        return self.request("PATCH", self._dev(bus, dev_id) + "/config", params)

    def persist(self, bus: str, dev_id: int) -> dict:
        return self.request("POST", self._dev(bus, dev_id) + "/config/persist")

    def scan(self, bus: str, first: int = 1, last: int = 16) -> List[int]:
        return self.request("POST", self._bus(bus) + "/scan", {"first": first, "last": last})["found"]

    def estop(self, bus: Optional[str] = None) -> dict:
        """Disable every joint (of one bus, or of every bus) ahead of anything queued."""
        path = "/api/v1/estop" if bus is None else self._bus(bus) + "/estop"
        return self.request("POST", path)

    def params(self) -> List[dict]:
        return self.request("GET", "/api/v1/params")["params"]

    # ------------------------------------------------------------- WebSocket

    def ws_url(self) -> str:
        scheme = "wss" if self.url.startswith("https") else "ws"
        return scheme + ":" + self.url.split(":", 1)[1] + "/api/v1/ws"

    def telemetry(self, devices: Optional[Iterable[int]] = None, rate_hz: float = 50,
                  buses: Optional[Iterable[str]] = None, fields: Optional[Iterable[str]] = None):
        """`async for sample in client.telemetry([1, 2], 100)`: one `Telemetry` per message."""
        return telemetry(self, devices, rate_hz, buses, fields)

    def setpoints(self, hold_timeout_ms: int = 200, policy: str = "hold") -> SetpointStream:
        """`async with client.setpoints() as s: await s.send([...])`: the watchdog is
        armed while the block runs and disarmed before the socket closes."""
        return SetpointStream(self, hold_timeout_ms, policy)
