#!/usr/bin/env python3
"""Teleoperation example for jointd's WebSocket (jointd.ws.v1), on the
jointd-client package.

Streams a sine wave to every joint at 500 Hz for 10 s, asks for an ack of
every batch, and prints the acknowledged setpoint-to-wire latency (p50/p99,
as the daemon measured it: accepted -> last byte of the carrying frame on the
wire), the client's round trip (send -> ack received), and the telemetry rate
it received.

    cargo run --release -- --sim 16                  # in another terminal
    pip install ./clients/python
    python3 examples/teleop.py --enable              # enables the joints first

Without --enable the joints must already be enabled (the daemon never moves a
disabled joint; targets to one are rejected with `wrong_state`). The
watchdog is armed while the stream runs: if this script dies, the joints
freeze where they are. On a normal finish it disarms the watchdog, then
closes the socket, so the daemon logs no watchdog firing.
"""

import argparse
import asyncio
import math
import sys
import time
from typing import Any, Dict, List, Sequence

try:
    from jointd_client import Jointd
except ImportError:
    sys.exit("needs the client package: pip install ./clients/python")


def percentile(values: Sequence[float], p: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(round(p / 100 * (len(s) - 1))))]


async def count_telemetry(client: Jointd, rate_hz: float, counter: List[int],
                          stop: asyncio.Event) -> None:
    async for _ in client.telemetry(rate_hz=rate_hz):
        if stop.is_set():
            return
        counter[0] += 1


async def run(args: argparse.Namespace) -> int:
    client = Jointd(args.url, token=args.token)
    joints = [(b.name, d.id) for b in client.buses() for d in client.devices(b.name)]
    if not joints:
        sys.exit("the daemon knows no joints")
    print(f"{len(joints)} joints on {len({b for b, _ in joints})} bus(es)")
    if args.enable:
        for bus in {b for b, _ in joints}:
            client.enable_all(bus, wait=True)  # returns once every joint runs (~1 s to align)

    telemetry, stop = [0], asyncio.Event()
    counter = asyncio.create_task(count_telemetry(client, args.telemetry_hz, telemetry, stop))
    server_latency: List[float] = []
    round_trip: List[float] = []
    errors: List[BaseException] = []
    period = 1.0 / args.rate_hz
    async with client.setpoints(hold_timeout_ms=200, policy="hold") as stream:
        start = time.perf_counter()
        seq = 0
        pending: "List[asyncio.Future[Dict[str, Any]]]" = []
        while (now := time.perf_counter()) - start < args.seconds:
            t = now - start
            targets = [{"bus": b, "id": d,
                        "position_deg": round(args.amplitude * math.sin(2 * math.pi * args.freq * t + i * 0.3), 3),
                        "speed_dps": 200}
                       for i, (b, d) in enumerate(joints)]
            seq += 1
            sent = time.perf_counter()
            fut = await stream.send_nowait(targets)
            def acked(f: "asyncio.Future[Dict[str, Any]]", sent: float = sent) -> None:
                if not f.exception():
                    round_trip.append((time.perf_counter() - sent) * 1e6)

            fut.add_done_callback(acked)
            pending.append(fut)
            await asyncio.sleep(max(0.0, start + seq * period - time.perf_counter()))
        elapsed = time.perf_counter() - start
        done, _ = await asyncio.wait(pending, timeout=1.0)  # late acks
        for f in done:
            exc = f.exception()
            if exc is not None:
                errors.append(exc)
            else:
                server_latency.append(f.result()["latency_us"])
    stop.set()
    counter.cancel()
    for e in errors[:3]:
        print("error:", e, file=sys.stderr)

    print(f"sent {seq} batches in {elapsed:.2f} s ({seq / elapsed:.0f} Hz), {len(server_latency)} acked, {len(errors)} errors")
    print(f"setpoint-to-wire latency (daemon): p50 {percentile(server_latency, 50) / 1000:.2f} ms, "
          f"p99 {percentile(server_latency, 99) / 1000:.2f} ms")
    print(f"client round trip (send -> ack):   p50 {percentile(round_trip, 50) / 1000:.2f} ms, "
          f"p99 {percentile(round_trip, 99) / 1000:.2f} ms")
    print(f"telemetry received: {telemetry[0] / elapsed:.1f} messages/s (subscribed {args.telemetry_hz} Hz)")
    return 0 if server_latency and not errors else 1


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--url", default="http://127.0.0.1:8080")
    p.add_argument("--token", default=None)
    p.add_argument("--enable", action="store_true", help="enable every joint first (they will move!)")
    p.add_argument("--rate-hz", type=float, default=500)
    p.add_argument("--seconds", type=float, default=10)
    p.add_argument("--amplitude", type=float, default=30.0, help="degrees")
    p.add_argument("--freq", type=float, default=0.5, help="sine frequency, Hz")
    p.add_argument("--telemetry-hz", type=float, default=100)
    args = p.parse_args()
    sys.exit(asyncio.run(run(args)))


if __name__ == "__main__":
    main()
