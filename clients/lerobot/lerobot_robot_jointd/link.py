"""One WebSocket to the daemon for one hand: telemetry kept up to date by a
reader thread (so an observation is a dictionary read, not a round trip),
and setpoints streamed under the daemon's teleoperation watchdog (a policy
process that dies leaves the hand held, or disabled, within
`hold_timeout_ms`).

The link never enables anything and never begins a new stream by itself:
once an e-stop, a disable, a reset, a fault or a mode change ended a
joint's stream, every later `send` raises `HandStopped` until the caller
makes a new link (the robot's `connect()`, which enables on purpose).
"""

from __future__ import annotations

import collections
import itertools
import json
import threading
import time
import urllib.parse
from dataclasses import dataclass
from typing import Any, Deque, Dict, Iterable, List, Optional, Sequence, Tuple

from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.sync.client import ClientConnection, connect

from jointd_client.errors import ws_error

# What a robot's observation can carry per joint, by telemetry field
# (`bus`, `id`, `online` and `age_ms` come always).
FIELDS = ("angle_deg", "speed_dps", "q_current_a", "state")

JointKey = Tuple[str, int]


class LinkError(RuntimeError):
    """The daemon refused the link, or the link broke."""


class HandStopped(LinkError):
    """A joint's stream was ended by the daemon (e-stop, disable, reset,
    fault, mode change): nothing more is sent until a new `connect()`."""


@dataclass(frozen=True)
class Sample:
    """The newest telemetry of one joint, with when this process took it."""

    fields: Dict[str, Any]
    # The daemon's age of the sample when the message was built, ms.
    age_ms: float
    # time.monotonic() when the reader took the message.
    taken_at: float


class HandLink:
    """A WebSocket for the joints `joints` (bus, id): call `open()`, then
    `latest()` / `send()`; `close()` ends it (the watchdog disarmed first,
    so a client that simply finished is not a stopped stream)."""

    def __init__(self, ws_url: str, token: Optional[str], joints: Sequence[JointKey],
                 rate_hz: float, client_name: str):
        query = urllib.parse.urlencode({"client": client_name})
        self._url = f"{ws_url}?{query}"
        self._token = token
        self._joints = list(joints)
        self._rate_hz = rate_hz
        self._seq = itertools.count(1)
        self._lock = threading.Lock()
        self._latest: Dict[JointKey, Sample] = {}
        self._fresh = threading.Condition(self._lock)
        self._replies: Dict[int, Dict[str, Any]] = {}
        self._replied = threading.Condition(self._lock)
        # Messages sent with a `seq` whose reply (or refusal) is awaited.
        self._pending_calls: set[int] = set()
        self._stopped: Optional[str] = None
        self._refused: Optional[Exception] = None
        self._closed: Optional[str] = None
        self._ws: Optional[ClientConnection] = None
        self._reader: Optional[threading.Thread] = None
        self.welcome: Dict[str, Any] = {}
        self.messages = 0
        # Batches sent with `measure=True`: when each was sent, and for each
        # acked one, (sent -> ack received, ms; the daemon's accepted -> on
        # the wire, ms). The ack's trip back makes the first an upper bound.
        self._measured: Dict[int, float] = {}
        self.latencies: Deque[Tuple[float, float]] = collections.deque(maxlen=100_000)

    # ------------------------------------------------------------ lifecycle

    def open(self, timeout: float = 5.0) -> None:
        headers = {"Authorization": f"Bearer {self._token}"} if self._token else None
        try:
            # Entered as a context manager (newer websockets warn otherwise)
            # and left in close().
            self._ws = connect(self._url, additional_headers=headers, open_timeout=timeout,
                               max_size=2**22, compression=None).__enter__()
        except (OSError, InvalidHandshake, TimeoutError) as e:
            raise LinkError(f"the WebSocket {self._url} could not be opened: {e}") from None
        self.welcome = json.loads(self._ws.recv(timeout=timeout))
        self._reader = threading.Thread(target=self._read, name="jointd-link", daemon=True)
        self._reader.start()
        buses = sorted({bus for bus, _ in self._joints})
        ids = sorted({i for _, i in self._joints})
        self.call({"type": "subscribe", "buses": buses, "devices": ids,
                   "fields": list(FIELDS), "rate_hz": self._rate_hz}, "subscribed", timeout)

    def arm_watchdog(self, hold_timeout_ms: int, policy: str, timeout: float = 5.0) -> None:
        self.call({"type": "watchdog", "hold_timeout_ms": hold_timeout_ms, "policy": policy},
                  "watchdog_set", timeout)

    def close(self) -> None:
        ws = self._ws
        if ws is None:
            return
        try:
            if self._closed is None:
                self.call({"type": "watchdog", "hold_timeout_ms": 0, "policy": "hold"},
                          "watchdog_set", 2.0)
        except LinkError:
            pass
        ws.close()
        if self._reader is not None:
            self._reader.join(timeout=2.0)
        self._ws = None

    @property
    def is_open(self) -> bool:
        return self._ws is not None and self._closed is None

    # ------------------------------------------------------------- reading

    def _read(self) -> None:
        ws = self._ws
        assert ws is not None
        wanted = set(self._joints)
        try:
            for raw in ws:
                msg = json.loads(raw)
                kind = msg.get("type")
                self.messages += 1
                if kind == "telemetry":
                    now = time.monotonic()
                    with self._lock:
                        for j in msg["joints"]:
                            key = (j["bus"], j["id"])
                            if key in wanted:
                                self._latest[key] = Sample(j, j.get("age_ms", 0.0), now)
                        self._fresh.notify_all()
                elif kind == "stream_ended":
                    with self._lock:
                        self._stopped = (f"joint {msg.get('id')} of bus {msg.get('bus')}: "
                                         f"{msg.get('reason')}")
                elif kind == "error":
                    ref = msg.get("ref_seq")
                    with self._lock:
                        if ref is not None and ref in self._pending_calls:
                            self._replies[ref] = msg
                            self._replied.notify_all()
                        else:
                            self._refused = ws_error(msg)
                elif kind == "ack" and msg.get("ref_seq") in self._measured:
                    sent = self._measured.pop(msg["ref_seq"])
                    self.latencies.append(((time.perf_counter() - sent) * 1e3,
                                           float(msg.get("latency_us", 0.0)) / 1e3))
                elif msg.get("ref_seq") is not None:
                    with self._lock:
                        if msg["ref_seq"] in self._pending_calls:
                            self._replies[msg["ref_seq"]] = msg
                            self._replied.notify_all()
        except ConnectionClosed as e:
            reason = e.rcvd.reason if e.rcvd is not None else "closed"
            with self._lock:
                self._closed = reason or "closed"
        finally:
            with self._lock:
                if self._closed is None:
                    self._closed = "closed"
                self._fresh.notify_all()
                self._replied.notify_all()

    def call(self, msg: Dict[str, Any], expect: str, timeout: float) -> Dict[str, Any]:
        """Sends `msg` with a `seq` and waits for its reply of type `expect`."""
        seq = next(self._seq)
        with self._lock:
            self._pending_calls.add(seq)
        self._send({**msg, "seq": seq})
        deadline = time.monotonic() + timeout
        with self._lock:
            try:
                while seq not in self._replies:
                    if self._closed is not None:
                        raise LinkError(f"the daemon closed the WebSocket: {self._closed}")
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise LinkError(f"no `{expect}` from the daemon within {timeout} s")
                    self._replied.wait(left)
                reply = self._replies.pop(seq)
            finally:
                self._pending_calls.discard(seq)
        if reply.get("type") == "error":
            raise LinkError(f"the daemon refused `{msg['type']}`: {reply.get('message')}")
        if reply.get("type") != expect:
            raise LinkError(f"expected `{expect}`, the daemon said `{reply.get('type')}`")
        return reply

    def wait_for_samples(self, timeout: float) -> None:
        """Until every joint has a sample."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while len(self._latest) < len(set(self._joints)):
                if self._closed is not None:
                    raise LinkError(f"the daemon closed the WebSocket: {self._closed}")
                left = deadline - time.monotonic()
                if left <= 0:
                    missing = [j for j in self._joints if j not in self._latest]
                    raise LinkError(f"no telemetry from {missing} within {timeout} s")
                self._fresh.wait(left)

    def latest(self) -> Dict[JointKey, Sample]:
        """The newest sample of each joint (a copy)."""
        with self._lock:
            if self._closed is not None:
                raise LinkError(f"the daemon closed the WebSocket: {self._closed}")
            return dict(self._latest)

    # ------------------------------------------------------------- writing

    def _send(self, msg: Dict[str, Any]) -> None:
        ws = self._ws
        if ws is None:
            raise LinkError("the link is not open")
        try:
            ws.send(json.dumps(msg, separators=(",", ":")))
        except ConnectionClosed:
            raise LinkError(f"the daemon closed the WebSocket: {self._closed or 'closed'}") from None

    def check(self) -> None:
        """Raises what stopped the link, if anything did."""
        with self._lock:
            stopped, refused, closed = self._stopped, self._refused, self._closed
            self._refused = None
        if stopped is not None:
            raise HandStopped(
                f"the hand was stopped ({stopped}); jointd does not start it again "
                "by itself: connect() again to enable it")
        if closed is not None:
            raise LinkError(f"the daemon closed the WebSocket: {closed}")
        if refused is not None:
            raise LinkError(f"the daemon refused the last setpoints: {refused}")

    def send(self, targets: Iterable[Dict[str, Any]], restart: bool = False,
             ack: bool = False, measure: bool = False) -> Optional[int]:
        """One batch of targets (`{"bus", "id", "position_deg"}`), without
        waiting; with `ack`, its `seq` (the ack comes to `wait_ack`); with
        `measure`, its ack's latencies go to `latencies`."""
        self.check()
        msg: Dict[str, Any] = {"type": "setpoints", "targets": list(targets)}
        if restart:
            msg["restart"] = True
        if measure and not ack:
            seq = next(self._seq)
            msg["seq"] = seq
            msg["ack"] = True
            self._measured[seq] = time.perf_counter()
            self._send(msg)
            return None
        if ack:
            seq = next(self._seq)
            msg["seq"] = seq
            msg["ack"] = True
            with self._lock:
                self._pending_calls.add(seq)
            self._send(msg)
            return seq
        self._send(msg)
        return None

    def wait_ack(self, seq: int, timeout: float) -> Dict[str, Any]:
        """The `ack` (or refusal) of the batch `send(..., ack=True)` numbered `seq`."""
        deadline = time.monotonic() + timeout
        with self._lock:
            try:
                while seq not in self._replies:
                    left = deadline - time.monotonic()
                    if left <= 0 or self._closed is not None:
                        raise LinkError(f"no ack of setpoints {seq} within {timeout} s")
                    self._replied.wait(left)
                reply = self._replies.pop(seq)
            finally:
                self._pending_calls.discard(seq)
        if reply.get("type") == "error":
            raise ws_error(reply)
        return reply


def joints_of(hand_view: Dict[str, Any]) -> List[Tuple[str, str, int]]:
    """A hand's joints from `GET /api/v1/hands`: (name, bus, id) in its order."""
    return [(j["name"], j["bus"], int(j["id"])) for j in hand_view["joints"]]
