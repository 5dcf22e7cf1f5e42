"""REST calls of jointd, a method for every operation of openapi/openapi.json
(each tagged with its `operationId`: tests/test_coverage.py fails on an
operation without one), with the standard library only.

Answers are the typed dicts of `jointd_client.schema` (plain dicts at run
time, checked by mypy), or the dataclasses of `jointd_client.models` where
those existed first.
"""

import json
import os
import socket
import time
import urllib.error
import urllib.parse
import urllib.request
from typing import (Any, AsyncIterator, Dict, Iterable, List, Mapping, Optional, Sequence,
                    cast)

from . import schema
from ._ops import operation
from .errors import NotConnected, Problem, Timeout, error_for
from .grasps import GraspCalls
from .models import ActionDone, Bus, Device, TargetAck
from .moves import Homing, Move
from .stream import SetpointStream, Telemetry, telemetry

DEFAULT_URL = "http://127.0.0.1:8080"


def _drop_none(**fields: Any) -> Dict[str, Any]:
    return {k: v for k, v in fields.items() if v is not None}


class Jointd(GraspCalls):
    """A daemon at `url` (default: `$JOINTD_URL`, else http://127.0.0.1:8080),
    with the bearer `token` (default: `$JOINTD_TOKEN`). Grasping:
    `jointd_client.grasps`."""

    def __init__(self, url: Optional[str] = None, token: Optional[str] = None,
                 timeout: float = 10.0):
        self.url = (url or os.environ.get("JOINTD_URL") or DEFAULT_URL).rstrip("/")
        self.token = token if token is not None else os.environ.get("JOINTD_TOKEN") or None
        self.timeout = timeout

    # ------------------------------------------------------------------ REST

    def _raw(self, method: str, path: str, body: Any = None,
             timeout: Optional[float] = None) -> bytes:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, method=method, data=data)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            wait = self.timeout if timeout is None else max(self.timeout, timeout)
            with urllib.request.urlopen(req, timeout=wait) as r:
                return cast(bytes, r.read())
        except urllib.error.HTTPError as e:
            text = e.read()
            try:
                problem = Problem.from_json(json.loads(text))
            except ValueError:
                problem = Problem(type="about:blank", title=str(e.reason or "HTTP error"),
                                  status=e.code, detail=text.decode(errors="replace"))
            raise error_for(problem) from None
        except (urllib.error.URLError, ConnectionError, socket.timeout) as e:
            reason = getattr(e, "reason", e)
            raise NotConnected(self.url, str(reason)) from None

    def request(self, method: str, path: str, body: Any = None,
                timeout: Optional[float] = None) -> Any:
        """One call; the decoded JSON answer, or a `JointdError`. `timeout`:
        how long it may take (s), if longer than the client's."""
        text = self._raw(method, path, body, timeout)
        return json.loads(text) if text else None

    def _bus(self, bus: str) -> str:
        return "/api/v1/buses/" + urllib.parse.quote(bus, safe="")

    def _dev(self, bus: str, id: int) -> str:
        return f"{self._bus(bus)}/devices/{int(id)}"

    @staticmethod
    def _name(name: str) -> str:
        return urllib.parse.quote(name, safe="")

    # --------------------------------------------------------------- buses

    @operation("list_buses")
    def buses(self) -> List[Bus]:
        return [Bus.from_json(b) for b in self.request("GET", "/api/v1/buses")["buses"]]

    @operation("get_bus")
    def bus(self, bus: str) -> Bus:
        """The bus view (`raw` holds all of it: counters, USB pipeline, …)."""
        return Bus.from_json(self.request("GET", self._bus(bus)))

    @operation("set_baud")
    def set_baud(self, bus: str, baud: int) -> schema.BaudRequest:
        """Every device, then the port, to `baud` (each device read back)."""
        return cast(schema.BaudRequest, self.request("PUT", self._bus(bus) + "/baud", {"baud": baud}))

    @operation("patch_bus_config")
    def set_bus_config(self, bus: str, include_unmanaged: bool = False,
                       **params: float) -> schema.BusPatchResult:
        """Write parameters to every device of the bus (RAM), each verified."""
        query = "?include_unmanaged=true" if include_unmanaged else ""
        return cast(schema.BusPatchResult,
                    self.request("PATCH", self._bus(bus) + "/config" + query, params))

    @operation("scan")
    def scan(self, bus: str, first: int = 1, last: int = 16) -> List[int]:
        found = self.request("POST", self._bus(bus) + "/scan", {"first": first, "last": last})
        return cast(List[int], found["found"])

    @operation("doctor")
    def doctor(self, bus: str, timeout: float = 70.0) -> Dict[str, Any]:
        """The doctor's report on the bus (`jointd doctor --json`, docs/hardware.md):
        its port, adapter, line and devices checked, and the config it proposes.
        The bus lends its port for the run (seconds; polling pauses); refused
        with a 409 while a joint of the bus is enabled."""
        return cast(Dict[str, Any], self.request("POST", self._bus(bus) + "/doctor",
                                                 timeout=timeout))

    @operation("frames")
    def frames(self, bus: str, limit: Optional[int] = None) -> schema.FrameLog:
        """The last frames on the wire, both ways (decoded)."""
        query = "" if limit is None else f"?limit={int(limit)}"
        return cast(schema.FrameLog, self.request("GET", self._bus(bus) + "/frames" + query))

    @operation("estop_all", "estop_bus")
    def estop(self, bus: Optional[str] = None) -> schema.EstopResult:
        """Disable every joint (of one bus, or of every bus) ahead of anything queued."""
        path = "/api/v1/estop" if bus is None else self._bus(bus) + "/estop"
        return cast(schema.EstopResult, self.request("POST", path))

    # ---------------------------------------------------- groups of joints

    @operation("enable_group")
    def enable_all(self, bus: str, ids: Optional[Iterable[int]] = None,
                   wait: bool = False, timeout: float = 5.0) -> ActionDone:
        """Enable `ids` (default every joint of the bus); with `wait`, return
        once each runs (`Timeout` if one does not within `timeout` s)."""
        body = {} if ids is None else {"ids": list(ids)}
        done = ActionDone.from_json(self.request("POST", self._bus(bus) + "/control/enable", body))
        if wait:
            self._wait_running(bus, done.ids, timeout)
        return done

    @operation("disable_group")
    def disable_all(self, bus: str, ids: Optional[Iterable[int]] = None) -> ActionDone:
        body = {} if ids is None else {"ids": list(ids)}
        return ActionDone.from_json(self.request("POST", self._bus(bus) + "/control/disable", body))

    @operation("mode_group")
    def set_mode_all(self, bus: str, mode: str, ids: Optional[Iterable[int]] = None) -> ActionDone:
        body = _drop_none(mode=mode, ids=None if ids is None else list(ids))
        return ActionDone.from_json(self.request("PUT", self._bus(bus) + "/control/mode", body))

    @operation("target_group")
    def targets(self, bus: str, targets: Sequence[Mapping[str, Any]]) -> TargetAck:
        """Several joints' targets at once (`[{"id": 1, "position_deg": 10}, …]`)."""
        return TargetAck.from_json(self.request("PUT", self._bus(bus) + "/control/targets",
                                                {"targets": [dict(t) for t in targets]}))

    # ------------------------------------------------------------- devices

    @operation("list_devices")
    def devices(self, bus: str) -> List[Device]:
        return [Device.from_json(d) for d in self.request("GET", self._bus(bus) + "/devices")["devices"]]

    @operation("get_device")
    def device(self, bus: str, id: int, fresh: bool = False) -> schema.DeviceDetail:
        """The full device view (INFO_01/INFO_02 decoded, raw bytes beside)."""
        return cast(schema.DeviceDetail,
                    self.request("GET", self._dev(bus, id) + ("?fresh=true" if fresh else "")))

    @operation("enable_one")
    def enable(self, bus: str, id: int, wait: bool = False, timeout: float = 5.0) -> ActionDone:
        """Enable one joint; with `wait`, return once it runs (it aligns for
        about a second first; `Timeout` after `timeout` s)."""
        done = ActionDone.from_json(self.request("POST", self._dev(bus, id) + "/enable"))
        if wait:
            self._wait_running(bus, [id], timeout)
        return done

    @operation("disable_one")
    def disable(self, bus: str, id: int) -> ActionDone:
        return ActionDone.from_json(self.request("POST", self._dev(bus, id) + "/disable"))

    @operation("target_one")
    def target(self, bus: str, id: int, position_deg: Optional[float] = None,
               speed_dps: Optional[float] = None) -> TargetAck:
        body = _drop_none(position_deg=position_deg, speed_dps=speed_dps)
        return TargetAck.from_json(self.request("PUT", self._dev(bus, id) + "/target", body))

    @operation("mode_one")
    def set_mode(self, bus: str, id: int, mode: str) -> ActionDone:
        return ActionDone.from_json(self.request("PUT", self._dev(bus, id) + "/mode", {"mode": mode}))

    @operation("jog")
    def jog(self, bus: str, id: int, direction: str) -> ActionDone:
        """One jog step, `cw` or `ccw`."""
        return ActionDone.from_json(self.request("POST", self._dev(bus, id) + "/jog",
                                                 {"direction": direction}))

    @operation("rezero")
    def rezero(self, bus: str, id: int) -> ActionDone:
        """Make the joint's present angle its zero."""
        return ActionDone.from_json(self.request("POST", self._dev(bus, id) + "/rezero"))

    @operation("change_id")
    def change_id(self, bus: str, id: int, new_id: int) -> schema.IdResult:
        return cast(schema.IdResult, self.request("PUT", self._dev(bus, id) + "/id", {"new_id": new_id}))

    @operation("read_config")
    def config(self, bus: str, id: int) -> schema.ConfigView:
        """Every parameter read from the device now: `{key: {value, raw, unit, index}}`."""
        return cast(schema.ConfigView, self.request("GET", self._dev(bus, id) + "/config"))

    @operation("patch_config")
    def set_config(self, bus: str, id: int, **params: float) -> schema.PatchResult:
        """Write any subset of parameters (RAM), each verified by read-back."""
        return cast(schema.PatchResult, self.request("PATCH", self._dev(bus, id) + "/config", params))

    @operation("persist")
    def persist(self, bus: str, id: int) -> schema.PersistResult:
        """Write the device's RAM parameters to its flash."""
        return cast(schema.PersistResult, self.request("POST", self._dev(bus, id) + "/config/persist"))

    @operation("get_calibration")
    def calibration(self, bus: str, id: int) -> schema.CalibrationView:
        return cast(schema.CalibrationView, self.request("GET", self._dev(bus, id) + "/calibration"))

    @operation("put_calibration")
    def set_calibration(self, bus: str, id: int, offset_deg: Optional[float] = None,
                        flip: Optional[bool] = None,
                        range_deg: Optional[Sequence[float]] = None) -> schema.CalibrationView:
        body = _drop_none(offset_deg=offset_deg, flip=flip,
                          range_deg=None if range_deg is None else list(range_deg))
        return cast(schema.CalibrationView,
                    self.request("PUT", self._dev(bus, id) + "/calibration", body))

    @operation("delete_calibration")
    def clear_calibration(self, bus: str, id: int) -> schema.CalibrationView:
        return cast(schema.CalibrationView, self.request("DELETE", self._dev(bus, id) + "/calibration"))

    def _wait_running(self, bus: str, ids: Optional[Iterable[int]], timeout: float) -> None:
        """Until every joint of `ids` (default: every one of the bus) runs."""
        wanted = None if ids is None else set(ids)
        deadline = time.monotonic() + timeout
        while True:
            rows = [d for d in self.devices(bus) if wanted is None or d.id in wanted]
            if rows and all(d.state == "run" for d in rows):
                return
            if time.monotonic() >= deadline:
                states = {d.id: d.state for d in rows}
                raise Timeout(Problem(type="urn:jointd:client:timeout", title="Timeout", status=0,
                                      detail=f"joints not running after {timeout} s: {states}"))
            time.sleep(0.02)

    # --------------------------------------------------------------- moves

    @operation("start_move")
    def move(self, joints: Sequence[Mapping[str, Any]], duration_ms: Optional[float] = None,
             method: Optional[str] = None, max_velocity_dps: Optional[float] = None,
             max_acceleration_dps2: Optional[float] = None,
             waypoints: Optional[Sequence[Mapping[str, Any]]] = None,
             wait: bool = False, timeout: Optional[float] = None) -> Move:
        """A smooth move of `joints` (`[{"bus": "sim0", "id": 1, "position_deg": 30}]`,
        or `{"hand": …, "joint": …}`); a `Move` handle. With `wait`, returns
        once it ended (`move.state` says how)."""
        body = _drop_none(joints=[dict(j) for j in joints], duration_ms=duration_ms, method=method,
                          max_velocity_dps=max_velocity_dps,
                          max_acceleration_dps2=max_acceleration_dps2,
                          waypoints=None if waypoints is None else [dict(w) for w in waypoints])
        return self._started_move("/api/v1/moves", body, wait, timeout)

    @operation("get_move")
    def get_move(self, move_id: int) -> schema.MoveView:
        return cast(schema.MoveView, self.request("GET", f"/api/v1/moves/{int(move_id)}"))

    @operation("stop_move")
    def stop_move(self, move_id: int) -> schema.MoveView:
        return cast(schema.MoveView, self.request("DELETE", f"/api/v1/moves/{int(move_id)}"))

    # ------------------------------------------------------- hands, poses

    @operation("list_hands")
    def hands(self) -> schema.HandList:
        return cast(schema.HandList, self.request("GET", "/api/v1/hands"))

    @operation("hand_calibration")
    def hand_calibration(self, hand: str) -> schema.HandCalibration:
        return cast(schema.HandCalibration,
                    self.request("GET", f"/api/v1/hands/{self._name(hand)}/calibration"))

    def _pose(self, hand: str, name: str) -> str:
        return f"/api/v1/hands/{self._name(hand)}/poses/{self._name(name)}"

    @operation("get_pose")
    def pose(self, hand: str, name: str) -> schema.PoseView:
        return cast(schema.PoseView, self.request("GET", self._pose(hand, name)))

    @operation("put_pose")
    def save_pose(self, hand: str, name: str,
                  positions_deg: Optional[Mapping[str, float]] = None) -> schema.PoseView:
        """Save a pose: the given angles, or (none given) where the joints are now."""
        body: Dict[str, Any] = ({"from_current": True} if positions_deg is None
                                else {"positions_deg": dict(positions_deg)})
        return cast(schema.PoseView, self.request("PUT", self._pose(hand, name), body))

    @operation("delete_pose")
    def delete_pose(self, hand: str, name: str) -> schema.PoseView:
        return cast(schema.PoseView, self.request("DELETE", self._pose(hand, name)))

    @operation("go_to_pose")
    def go_to_pose(self, hand: str, name: str, duration_ms: Optional[float] = None,
                   method: Optional[str] = None, max_velocity_dps: Optional[float] = None,
                   max_acceleration_dps2: Optional[float] = None,
                   wait: bool = False, timeout: Optional[float] = None) -> Move:
        """A move of the hand to a saved pose; a `Move` handle (see `move`)."""
        body = _drop_none(duration_ms=duration_ms, method=method, max_velocity_dps=max_velocity_dps,
                          max_acceleration_dps2=max_acceleration_dps2)
        return self._started_move(self._pose(hand, name) + "/go", body, wait, timeout)

    def _started_move(self, path: str, body: Dict[str, Any], wait: bool,
                      timeout: Optional[float]) -> Move:
        """POSTs a move at `path`; its handle, waited for with `wait`."""
        m = Move(self, cast(schema.MoveView, self.request("POST", path, body)))
        if wait:
            m.wait(timeout)
        return m

    # -------------------------------------------------------------- homing

    @operation("start_homing")
    def home(self, joints: Optional[Sequence[Mapping[str, Any]]] = None, hand: Optional[str] = None,
             wait: bool = False, timeout: Optional[float] = None, **options: Any) -> Homing:
        """Home joints (or a whole `hand`) against their end stops; a `Homing`
        handle. `options`: `direction`, `speed_dps`, `current_limit_a`,
        `max_travel_deg`, `backoff_deg`, `stop_at_deg`, `timeout_ms`."""
        body = _drop_none(joints=None if joints is None else [dict(j) for j in joints], hand=hand,
                          **options)
        h = Homing(self, cast(schema.HomingView, self.request("POST", "/api/v1/homing", body)))
        if wait:
            h.wait(timeout)
        return h

    @operation("get_homing")
    def get_homing(self, homing_id: int) -> schema.HomingView:
        return cast(schema.HomingView, self.request("GET", f"/api/v1/homing/{int(homing_id)}"))

    # ---------------------------------------------------------- recordings

    @operation("list_recordings")
    def recordings(self) -> schema.RecordingList:
        return cast(schema.RecordingList, self.request("GET", "/api/v1/recordings"))

    @operation("start_recording")
    def start_recording(self, buses: Optional[Iterable[str]] = None,
                        duration_s: Optional[float] = None,
                        bag_compatible: Optional[bool] = None) -> schema.RecordingView:
        body = _drop_none(buses=None if buses is None else list(buses), duration_s=duration_s,
                          bag_compatible=bag_compatible)
        return cast(schema.RecordingView, self.request("POST", "/api/v1/recordings", body))

    @operation("get_recording")
    def recording(self, recording_id: int) -> schema.RecordingView:
        return cast(schema.RecordingView, self.request("GET", f"/api/v1/recordings/{int(recording_id)}"))

    @operation("stop_recording")
    def stop_recording(self, recording_id: int) -> schema.RecordingView:
        return cast(schema.RecordingView,
                    self.request("DELETE", f"/api/v1/recordings/{int(recording_id)}"))

    @operation("recording_file")
    def recording_file(self, recording_id: int, path: Optional[str] = None) -> bytes:
        """The MCAP file's bytes (also written to `path` if given)."""
        data = self._raw("GET", f"/api/v1/recordings/{int(recording_id)}/file")
        if path is not None:
            with open(path, "wb") as f:
                f.write(data)
        return data

    # ------------------------------------------------------ the daemon

    @operation("param_table")
    def params(self) -> List[schema.ParamInfo]:
        return cast(List[schema.ParamInfo], self.request("GET", "/api/v1/params")["params"])

    @operation("ros2_status")
    def ros2(self) -> schema.Ros2View:
        return cast(schema.Ros2View, self.request("GET", "/api/v1/ros2"))

    @operation("healthz")
    def health(self) -> schema.Health:
        return cast(schema.Health, self.request("GET", "/healthz"))

    @operation("caller")
    def caller(self) -> schema.CallerView:
        """The token this client uses, by its name and scope (never the token)."""
        return cast(schema.CallerView, self.request("GET", "/api/v1/caller"))

    @operation("readyz")
    def ready(self) -> schema.Readiness:
        """Whether every bus is up (`Unavailable` if not: 503 carries the same body)."""
        return cast(schema.Readiness, self.request("GET", "/readyz"))

    @operation("metrics")
    def metrics(self) -> str:
        """The Prometheus exposition text."""
        return self._raw("GET", "/metrics").decode()

    # ------------------------------------------------------------- WebSocket

    def ws_url(self) -> str:
        scheme = "wss" if self.url.startswith("https") else "ws"
        return scheme + ":" + self.url.split(":", 1)[1] + "/api/v1/ws"

    def telemetry(self, devices: Optional[Iterable[int]] = None, rate_hz: float = 50,
                  buses: Optional[Iterable[str]] = None,
                  fields: Optional[Iterable[str]] = None) -> AsyncIterator[Telemetry]:
        """`async for sample in client.telemetry([1, 2], 100)`: one `Telemetry` per message."""
        return telemetry(self, devices, rate_hz, buses, fields)

    def setpoints(self, hold_timeout_ms: int = 200, policy: str = "hold") -> SetpointStream:
        """`async with client.setpoints() as s: await s.send([...])`: the watchdog is
        armed while the block runs and disarmed before the socket closes."""
        return SetpointStream(self, hold_timeout_ms, policy)
