"""The WebSocket side (docs/websocket.md, `jointd.ws.v1`): telemetry as an
async iterator, setpoints with acks under the teleoperation watchdog."""

import asyncio
import itertools
import json
from dataclasses import dataclass
from types import TracebackType
from typing import (Any, AsyncIterator, Dict, Iterable, List, Optional, Protocol, Type,
                    TypedDict)

import websockets
from websockets.asyncio.client import ClientConnection, connect

from .errors import NotConnected, ws_error


class Endpoint(Protocol):
    """Where the socket goes (`Jointd` is one)."""

    token: Optional[str]

    def ws_url(self) -> str: ...


class JointSample(TypedDict, total=False):
    """One joint of a `telemetry` message (docs/websocket.md): the fields
    the subscription asked for (all by default)."""

    bus: str
    id: int
    online: bool
    age_ms: float
    angle_deg: Optional[float]
    target_deg: Optional[float]
    target_known: bool
    speed_dps: Optional[float]
    q_current_a: Optional[float]
    state: Optional[str]
    disabled_reason: Optional[str]
    fault: Optional[str]
    temp_c: Optional[float]
    vbus_v: Optional[float]


@dataclass(frozen=True)
class Telemetry:
    """One `telemetry` message: `joints` is a list of per-joint dicts
    (`bus`, `id`, `online`, `age_ms`, `angle_deg`, ...)."""

    seq: int
    t_ms: float
    dropped: int
    joints: List[JointSample]


async def _open(client: Endpoint) -> ClientConnection:
    headers = {"Authorization": f"Bearer {client.token}"} if client.token else None
    try:
        return await connect(client.ws_url(), additional_headers=headers, max_queue=None)
    except (OSError, websockets.exceptions.InvalidHandshake) as e:
        raise NotConnected(client.ws_url(), str(e)) from None


async def telemetry(client: Endpoint, devices: Optional[Iterable[int]], rate_hz: float,
                    buses: Optional[Iterable[str]],
                    fields: Optional[Iterable[str]]) -> AsyncIterator[Telemetry]:
    async with await _open(client) as ws:
        sub: Dict[str, Any] = {"type": "subscribe", "seq": 1, "rate_hz": rate_hz}
        if devices is not None:
            sub["devices"] = list(devices)
        if buses is not None:
            sub["buses"] = list(buses)
        if fields is not None:
            sub["fields"] = list(fields)
        await ws.send(json.dumps(sub))
        async for raw in ws:
            msg = json.loads(raw)
            if msg.get("type") == "telemetry":
                yield Telemetry(seq=msg["seq"], t_ms=msg["t_ms"], dropped=msg.get("dropped", 0),
                                joints=msg["joints"])
            elif msg.get("type") == "error":
                raise ws_error(msg)


class SetpointStream:
    """Streams setpoint batches. On enter the watchdog is armed (`policy`
    after `hold_timeout_ms` without a batch); on a normal exit it is
    disarmed first and the socket closed cleanly, so the daemon logs no
    watchdog firing for a client that simply finished."""

    def __init__(self, client: Endpoint, hold_timeout_ms: int, policy: str):
        self._client = client
        self._hold = hold_timeout_ms
        self._policy = policy
        self._seq = itertools.count(1)
        self._pending: Dict[int, "asyncio.Future[Dict[str, Any]]"] = {}
        self._replies: Dict[int, "asyncio.Future[Dict[str, Any]]"] = {}
        self._socket: Optional[ClientConnection] = None
        self._reader: Optional["asyncio.Task[None]"] = None
        self.errors: List[Dict[str, Any]] = []
        self.welcome: Optional[Dict[str, Any]] = None

    @property
    def _ws(self) -> ClientConnection:
        if self._socket is None:
            raise RuntimeError("use the stream in `async with client.setpoints() as s:`")
        return self._socket

    async def __aenter__(self) -> "SetpointStream":
        self._socket = await _open(self._client)
        self.welcome = json.loads(await self._ws.recv())
        self._reader = asyncio.create_task(self._read())
        await self._call({"type": "watchdog", "hold_timeout_ms": self._hold, "policy": self._policy})
        return self

    async def __aexit__(self, exc_type: Optional[Type[BaseException]],
                        exc: Optional[BaseException], tb: Optional[TracebackType]) -> None:
        try:
            if exc_type is None:
                await self._call({"type": "watchdog", "hold_timeout_ms": 0, "policy": self._policy})
        finally:
            if self._reader:
                self._reader.cancel()
            await self._ws.close()

    async def _read(self) -> None:
        async for raw in self._ws:
            msg = json.loads(raw)
            ref = msg.get("ref_seq")
            kind = msg.get("type")
            if kind == "ack" and ref in self._pending:
                self._pending.pop(ref).set_result(msg)
            elif kind == "error":
                self.errors.append(msg)
                for table in (self._pending, self._replies):
                    if ref in table:
                        table.pop(ref).set_exception(ws_error(msg))
            elif ref in self._replies:
                self._replies.pop(ref).set_result(msg)

    async def _call(self, msg: Dict[str, Any], timeout: float = 5.0) -> Dict[str, Any]:
        seq = next(self._seq)
        fut: "asyncio.Future[Dict[str, Any]]" = asyncio.get_running_loop().create_future()
        self._replies[seq] = fut
        await self._ws.send(json.dumps({**msg, "seq": seq}))
        return await asyncio.wait_for(fut, timeout)

    async def send_nowait(self, targets: Iterable[Dict[str, Any]]) -> "asyncio.Future[Dict[str, Any]]":
        """One batch asking for an ack, without waiting for it: the returned
        future resolves to the ack (or raises if the batch was refused). For
        streaming at a fixed rate, where waiting would slow the stream."""
        seq = next(self._seq)
        fut: "asyncio.Future[Dict[str, Any]]" = asyncio.get_running_loop().create_future()
        self._pending[seq] = fut
        await self._ws.send(json.dumps({"type": "setpoints", "seq": seq, "ack": True, "targets": list(targets)}))
        return fut

    async def send(self, targets: Iterable[Dict[str, Any]], ack: bool = True,
                   timeout: float = 5.0) -> Optional[Dict[str, Any]]:
        """One batch (`[{"bus":..., "id":..., "position_deg":..., "speed_dps":...}]`).
        With `ack`, waits until every target is on the wire and returns the
        ack (`latency_us` = accepted -> on the wire); a refused batch raises."""
        seq = next(self._seq)
        msg = {"type": "setpoints", "seq": seq, "ack": ack, "targets": list(targets)}
        if not ack:
            await self._ws.send(json.dumps(msg))
            return None
        fut: "asyncio.Future[Dict[str, Any]]" = asyncio.get_running_loop().create_future()
        self._pending[seq] = fut
        await self._ws.send(json.dumps(msg))
        return await asyncio.wait_for(fut, timeout)

    async def enable(self, bus: str, ids: Optional[Iterable[int]] = None,
                     timeout: float = 10.0) -> Dict[str, Any]:
        """Enables the joints `ids` of `bus` (every joint without `ids`) on
        this socket, as `Jointd.enable_all` does over REST; returns the
        `done` reply once every joint confirmed it (a refusal raises).
        Ends every stream to those joints, as any enable does."""
        return await self._call(_drop_none(type="enable", bus=bus, ids=_ids(ids)), timeout)

    async def disable(self, bus: str, ids: Optional[Iterable[int]] = None,
                      timeout: float = 10.0) -> Dict[str, Any]:
        """Disables the joints `ids` of `bus` (every joint without `ids`);
        the `done` reply."""
        return await self._call(_drop_none(type="disable", bus=bus, ids=_ids(ids)), timeout)

    async def estop(self, bus: Optional[str] = None, timeout: float = 10.0) -> Dict[str, Any]:
        """The e-stop of `bus` (every bus without it), as `Jointd.estop`;
        the per-bus result (`stopped` false when a device could not be
        confirmed stopped). Any token may send it."""
        reply = await self._call(_drop_none(type="estop", bus=bus), timeout)
        result: Dict[str, Any] = reply["result"]
        return result


def _drop_none(**fields: Any) -> Dict[str, Any]:
    return {k: v for k, v in fields.items() if v is not None}


def _ids(ids: Optional[Iterable[int]]) -> Optional[List[int]]:
    return None if ids is None else list(ids)
