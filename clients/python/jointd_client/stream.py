"""The WebSocket side (docs/websocket.md, `jointd.ws.v1`): telemetry as an
async iterator, setpoints with acks under the teleoperation watchdog."""

import asyncio
import itertools
import json
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Optional

import websockets

from .errors import JointdError, Problem


@dataclass(frozen=True)
class Telemetry:
    """One `telemetry` message: `joints` is a list of per-joint dicts
    (`bus`, `dev_id`, `online`, `age_ms`, `angle_deg`, ...)."""

    seq: int
    t_ms: float
    dropped: int
    joints: List[Dict[str, Any]]


def _connect(client):
    headers = {"Authorization": f"Bearer {client.token}"} if client.token else None
    return websockets.connect(client.ws_url(), additional_headers=headers, max_queue=None)


def _ws_error(msg: dict) -> JointdError:
    return JointdError(Problem(type=f"urn:jointd:ws:{msg.get('code')}", title=str(msg.get("code")),
                               status=0, detail=str(msg.get("message")), field=msg.get("field")))


async def telemetry(client, devices, rate_hz, buses, fields):
    async with _connect(client) as ws:
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
                raise _ws_error(msg)


class SetpointStream:
    """Streams setpoint batches. On enter the watchdog is armed (`policy`
    after `hold_timeout_ms` without a batch); on a normal exit it is
    disarmed first and the socket closed cleanly, so the daemon logs no
    watchdog firing for a client that simply finished."""

    def __init__(self, client, hold_timeout_ms: int, policy: str):
        self._client = client
        self._hold = hold_timeout_ms
        self._policy = policy
        self._seq = itertools.count(1)
        self._pending: Dict[int, asyncio.Future] = {}
        self._replies: Dict[int, asyncio.Future] = {}
        self._ws = None
        self._reader = None
        self.errors: List[dict] = []
        self.welcome: Optional[dict] = None

    async def __aenter__(self) -> "SetpointStream":
        self._ws = await _connect(self._client).__aenter__()
        self.welcome = json.loads(await self._ws.recv())
        self._reader = asyncio.create_task(self._read())
        await self._call({"type": "watchdog", "hold_timeout_ms": self._hold, "policy": self._policy})
        return self

    async def __aexit__(self, *exc) -> None:
        try:
            if exc[0] is None:
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
                        table.pop(ref).set_exception(_ws_error(msg))
            elif ref in self._replies:
                self._replies.pop(ref).set_result(msg)

    async def _call(self, msg: dict, timeout: float = 5.0) -> dict:
        seq = next(self._seq)
        fut = asyncio.get_running_loop().create_future()
        self._replies[seq] = fut
        await self._ws.send(json.dumps({**msg, "seq": seq}))
        return await asyncio.wait_for(fut, timeout)

    async def send_nowait(self, targets: Iterable[dict]) -> "asyncio.Future":
        """One batch asking for an ack, without waiting for it: the returned
        future resolves to the ack (or raises if the batch was refused). For
        streaming at a fixed rate, where waiting would slow the stream."""
        seq = next(self._seq)
        fut = asyncio.get_running_loop().create_future()
        self._pending[seq] = fut
        await self._ws.send(json.dumps({"type": "setpoints", "seq": seq, "ack": True, "targets": list(targets)}))
        return fut

    async def send(self, targets: Iterable[dict], ack: bool = True, timeout: float = 5.0) -> Optional[dict]:
        """One batch (`[{"bus":..., "dev_id":..., "position_deg":..., "speed_rpm":...}]`).
        With `ack`, waits until every target is on the wire and returns the
        ack (`latency_us` = accepted -> on the wire); a refused batch raises."""
        seq = next(self._seq)
        msg = {"type": "setpoints", "seq": seq, "ack": ack, "targets": list(targets)}
        if not ack:
            await self._ws.send(json.dumps(msg))
            return None
        fut = asyncio.get_running_loop().create_future()
        self._pending[seq] = fut
        await self._ws.send(json.dumps(msg))
        return await asyncio.wait_for(fut, timeout)
