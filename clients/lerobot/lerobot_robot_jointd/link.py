"""One WebSocket to the daemon for one hand: telemetry kept up to date by a
reader thread (so an observation is a dictionary read, not a round trip),
and setpoints streamed under the daemon's teleoperation watchdog (a policy
process that dies leaves the hand held, or disabled, within
`hold_timeout_ms`).

The link never enables anything and never begins a stream again: once the
daemon ended a joint's stream (an e-stop, a disable, a reset, a fault, a
mode change, an enable by anyone) or refused a batch because the joint
cannot be driven, every later `send` raises `HandStopped` until the caller
makes a new link (the robot's `connect()`, which enables on purpose).
"""

from __future__ import annotations

import collections
import itertools
import json
import math
import threading
import time
import urllib.parse
from dataclasses import dataclass
from typing import Any, Deque, Dict, Iterable, List, Optional, Sequence, Set, Tuple

from websockets.exceptions import ConnectionClosed, WebSocketException
from websockets.sync.client import ClientConnection, connect

from jointd_client.errors import JointdError, ws_error

# What a robot's observation can carry per joint, by telemetry field
# (`bus`, `id`, `online` and `age_ms` come always).
FIELDS = ("angle_deg", "speed_dps", "q_current_a", "state")
# Events that stop a hand: seen while connecting, the connection fails.
STOPPING_EVENTS = {"estop", "device_reset", "fault", "device_offline", "bus_down"}

JointKey = Tuple[str, int]


class LinkError(RuntimeError):
    """The daemon refused the link, or the link broke."""


class HandStopped(LinkError):
    """The daemon ended a joint's stream (e-stop, disable, reset, fault,
    mode change, an enable by someone else) or refused to drive it:
    nothing more is sent until a new `connect()`."""


class Refused(LinkError):
    """The daemon refused a batch of setpoints (nothing of it applied),
    e.g. a target beyond a soft limit set since the robot connected."""

    def __init__(self, error: JointdError, code: str):
        super().__init__(f"the daemon refused the last setpoints: {error}")
        self.error = error
        self.code = code


@dataclass(frozen=True)
class Sample:
    """The newest telemetry of one joint, with when this process took it."""

    fields: Dict[str, Any]
    # The daemon's age of the sample when the message was built, ms.
    age_ms: float
    # time.monotonic() when the reader took the message.
    taken_at: float

    def age_now_ms(self, now: float) -> float:
        return self.age_ms + (now - self.taken_at) * 1e3

    def fresh(self, now: float, stale_s: float) -> bool:
        return bool(self.fields.get("online")) and self.age_now_ms(now) <= stale_s * 1e3


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
        self._wanted = set(self._joints)
        self._rate_hz = rate_hz
        self._seq = itertools.count(1)
        self._lock = threading.Lock()
        self._latest: Dict[JointKey, Sample] = {}
        self._fresh = threading.Condition(self._lock)
        self._replies: Dict[int, Dict[str, Any]] = {}
        self._replied = threading.Condition(self._lock)
        # Messages sent with a `seq` whose reply (or refusal) is awaited.
        self._pending_calls: Set[int] = set()
        self._stopped: Optional[str] = None
        self._refused: Optional[Refused] = None
        self._closed: Optional[str] = None
        self._ws: Optional[ClientConnection] = None
        self._reader: Optional[threading.Thread] = None
        # Stopping events heard since `open()` (a connect that saw one fails).
        self.stopping_events: List[Dict[str, Any]] = []
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
            self.welcome = json.loads(self._ws.recv(timeout=timeout))
        except (OSError, WebSocketException, TimeoutError, ValueError) as e:
            if self._ws is not None:
                self._ws.close()
                self._ws = None
            raise LinkError(f"the WebSocket {self._url} could not be opened: {e}") from None
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
        try:
            while True:
                self._take(json.loads(ws.recv()))
        except ConnectionClosed as e:
            reason = e.rcvd.reason if e.rcvd is not None else ""
            code = e.rcvd.code if e.rcvd is not None else None
            with self._lock:
                self._closed = f"{code} {reason}".strip() if code is not None else "the connection dropped"
        except (OSError, ValueError) as e:
            with self._lock:
                self._closed = f"the connection broke: {e}"
        finally:
            with self._lock:
                if self._closed is None:
                    self._closed = "closed"
                self._fresh.notify_all()
                self._replied.notify_all()

    def _take(self, msg: Dict[str, Any]) -> None:
        kind = msg.get("type")
        self.messages += 1
        if kind == "telemetry":
            now = time.monotonic()
            with self._lock:
                for j in msg["joints"]:
                    key = (j["bus"], j["id"])
                    if key in self._wanted:
                        self._latest[key] = Sample(j, float(j.get("age_ms") or 0.0), now)
                self._fresh.notify_all()
        elif kind == "event":
            ev = msg.get("event") or {}
            if ev.get("event") in STOPPING_EVENTS and self._concerns(ev):
                with self._lock:
                    self.stopping_events.append(ev)
        elif kind == "stream_ended":
            with self._lock:
                self._stopped = f"joint {msg.get('id')} of bus {msg.get('bus')}: {msg.get('reason')}"
        elif kind == "error":
            ref = msg.get("ref_seq")
            if ref is not None and ref in self._measured:
                self._measured.pop(ref, None)
            with self._lock:
                if ref is not None and ref in self._pending_calls:
                    self._replies[ref] = msg
                    self._replied.notify_all()
                elif msg.get("code") == "wrong_state":
                    # The joint cannot be driven (its stream ended, it is
                    # disabled, in a grasp or homing): said once by
                    # `stream_ended` too, unless that message was lost.
                    self._stopped = self._stopped or str(msg.get("message"))
                else:
                    self._refused = Refused(ws_error(msg), str(msg.get("code")))
        elif kind == "ack" and msg.get("ref_seq") in self._measured:
            sent = self._measured.pop(msg["ref_seq"])
            self.latencies.append(((time.perf_counter() - sent) * 1e3,
                                   float(msg.get("latency_us") or 0.0) / 1e3))
        elif msg.get("ref_seq") is not None:
            with self._lock:
                if msg["ref_seq"] in self._pending_calls:
                    self._replies[msg["ref_seq"]] = msg
                    self._replied.notify_all()

    def _concerns(self, ev: Dict[str, Any]) -> bool:
        """An event of a bus of these joints (and of one of them, if it names one)."""
        bus = ev.get("bus")
        if bus is not None and bus not in {b for b, _ in self._joints}:
            return False
        dev = ev.get("id")
        return dev is None or (bus, dev) in self._wanted

    def _await_reply(self, seq: int, what: str, timeout: float) -> Dict[str, Any]:
        deadline = time.monotonic() + timeout
        with self._lock:
            try:
                while seq not in self._replies:
                    if self._closed is not None:
                        raise LinkError(f"the daemon closed the WebSocket ({self._closed}) before {what}")
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise LinkError(f"no {what} from the daemon within {timeout} s")
                    self._replied.wait(left)
                return self._replies.pop(seq)
            finally:
                self._pending_calls.discard(seq)

    def call(self, msg: Dict[str, Any], expect: str, timeout: float) -> Dict[str, Any]:
        """Sends `msg` with a `seq` and waits for its reply of type `expect`."""
        seq = next(self._seq)
        with self._lock:
            self._pending_calls.add(seq)
        self._send({**msg, "seq": seq})
        reply = self._await_reply(seq, f"`{expect}`", timeout)
        if reply.get("type") == "error":
            raise LinkError(f"the daemon refused `{msg['type']}`: {reply.get('message')}")
        if reply.get("type") != expect:
            raise LinkError(f"expected `{expect}`, the daemon said `{reply.get('type')}`")
        return reply

    def wait_for_samples(self, timeout: float, ok: Any = None) -> None:
        """Until every joint has a sample (for which `ok(fields)` holds, if given)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while True:
                good = [j for j in self._wanted
                        if j in self._latest and (ok is None or ok(self._latest[j].fields))]
                if len(good) == len(self._wanted):
                    return
                if self._closed is not None:
                    raise LinkError(f"the daemon closed the WebSocket: {self._closed}")
                left = deadline - time.monotonic()
                if left <= 0:
                    missing = sorted(self._wanted - set(good))
                    raise LinkError(f"no telemetry as expected from {missing} within {timeout} s")
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
            ws.send(json.dumps(msg, separators=(",", ":"), allow_nan=False))
        except ConnectionClosed:
            raise LinkError(f"the daemon closed the WebSocket: {self._closed or 'closed'}") from None

    def check(self) -> None:
        """Raises what stopped the link, if anything did: `HandStopped`,
        `Refused` (once: the refusal of an earlier batch), `LinkError`."""
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
            raise refused

    def send(self, targets: Iterable[Dict[str, Any]], restart: bool = False,
             ack: bool = False, measure: bool = False) -> Optional[int]:
        """One batch of targets (`{"bus", "id", "position_deg"}`), without
        waiting; with `ack`, its `seq` (the ack comes to `wait_ack`); with
        `measure`, its ack's latencies go to `latencies`."""
        self.check()
        batch = list(targets)
        for t in batch:
            if not math.isfinite(float(t.get("position_deg", 0.0))):
                raise ValueError(f"target of joint {t.get('id')} is not a finite number: {t}")
        msg: Dict[str, Any] = {"type": "setpoints", "targets": batch}
        if restart:
            msg["restart"] = True
        if ack or measure:
            seq = next(self._seq)
            msg["seq"] = seq
            msg["ack"] = True
            if ack:
                with self._lock:
                    self._pending_calls.add(seq)
            else:
                self._measured[seq] = time.perf_counter()
            self._send(msg)
            return seq if ack else None
        self._send(msg)
        return None

    def wait_ack(self, seq: int, timeout: float) -> Dict[str, Any]:
        """The `ack` of the batch `send(..., ack=True)` numbered `seq`, or
        its refusal raised."""
        reply = self._await_reply(seq, f"the ack of setpoints {seq}", timeout)
        if reply.get("type") == "error":
            raise ws_error(reply)
        return reply



class Stale(LinkError):
    """A joint's telemetry is missing, offline or too old to use."""


def present(latest: Dict[JointKey, Sample], joints: Sequence[Tuple[str, str, int]],
            now: float, stale_s: float, whose: str) -> Dict[str, Dict[str, Any]]:
    """Each joint's newest telemetry by name, no older than `stale_s` and
    with an angle; otherwise `Stale` naming the joint (of `whose`) and why."""
    out: Dict[str, Dict[str, Any]] = {}
    for name, bus, i in joints:
        sample = latest.get((bus, i))
        angle = sample.fields.get("angle_deg") if sample is not None else None
        if sample is None or not sample.fresh(now, stale_s) or angle is None:
            why = ("never seen" if sample is None else "offline" if not sample.fields.get("online")
                   else "no angle" if angle is None
                   else f"its newest sample is {sample.age_now_ms(now):.0f} ms old")
            raise Stale(f"joint {name} ({bus}/{i}) of {whose}: {why}")
        out[name] = sample.fields
    return out
