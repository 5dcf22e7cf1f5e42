#!/usr/bin/env python3
"""Teleoperation example for jointd's WebSocket (jointd.ws.v1).

Streams a sine wave to every joint at 500 Hz for 10 s, asks for an ack of
every batch, and prints the acknowledged setpoint-to-wire latency (p50/p99,
as the daemon measured it: accepted -> last byte of the carrying frame on the
wire), the client's round trip (send -> ack received), and the telemetry rate
it received.

    jointd --sim 16                                  # in another terminal
    pip install websockets
    python3 examples/teleop.py --enable              # enables the joints first

Without --enable the joints must already be enabled (the daemon never moves a
disabled joint; targets to one are rejected with `wrong_state`). The
watchdog is armed: if this script stops, the joints freeze where they are.
"""

import argparse
import asyncio
import json
import math
import statistics
import sys
import time
import urllib.request

try:
    import websockets
except ImportError:
    sys.exit("needs the websockets package: pip install websockets")


def percentile(values, p):
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(round(p / 100 * (len(s) - 1))))]


def rest(base, method, path, token, body=None):
    req = urllib.request.Request(base + path, method=method,
                                 data=None if body is None else json.dumps(body).encode())
    req.add_header("Content-Type", "application/json")
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read() or b"null")


async def run(args):
    url = args.url + (f"?token={args.token}" if args.token else "")
    http = args.url.replace("ws://", "http://").replace("wss://", "https://").split("/api/")[0]
    async with websockets.connect(url, max_queue=None) as ws:
        welcome = json.loads(await ws.recv())
        joints = [(b["name"], d) for b in welcome["buses"] for d in b["devices"]]
        if not joints:
            sys.exit("the daemon knows no joints")
        print(f"{len(joints)} joints on {len(welcome['buses'])} bus(es)")
        if args.enable:
            for bus in {b for b, _ in joints}:
                rest(http, "POST", f"/api/v1/buses/{bus}/control/enable", args.token, {})
            await asyncio.sleep(args.align_s)  # the first enable aligns (~1 s)
        await ws.send(json.dumps({"type": "watchdog", "hold_timeout_ms": 200, "policy": "hold"}))
        await ws.send(json.dumps({"type": "subscribe", "rate_hz": args.telemetry_hz}))

        sent_at = {}
        server_latency, round_trip, errors = [], [], []
        telemetry = 0
        done = asyncio.Event()

        async def receive():
            nonlocal telemetry
            async for raw in ws:
                m = json.loads(raw)
                kind = m.get("type")
                if kind == "ack":
                    t0 = sent_at.pop(m["ref_seq"], None)
                    server_latency.append(m["latency_us"])
                    if t0 is not None:
                        round_trip.append((time.perf_counter() - t0) * 1e6)
                elif kind == "telemetry" and not done.is_set():
                    telemetry += 1
                elif kind == "error":
                    errors.append(m)
                    if len(errors) <= 3:
                        print("error:", m.get("code"), m.get("message"), file=sys.stderr)

        receiver = asyncio.create_task(receive())
        period = 1.0 / args.rate_hz
        start = time.perf_counter()
        seq = 0
        while (now := time.perf_counter()) - start < args.seconds:
            t = now - start
            targets = [{"bus": b, "dev_id": d,
                        "position_deg": round(args.amplitude * math.sin(2 * math.pi * args.freq * t + i * 0.3), 3),
                        "speed_rpm": 20000}
                       for i, (b, d) in enumerate(joints)]
            seq += 1
            sent_at[seq] = time.perf_counter()
            await ws.send(json.dumps({"type": "setpoints", "seq": seq, "ack": True, "targets": targets}))
            await asyncio.sleep(max(0.0, start + seq * period - time.perf_counter()))
        elapsed = time.perf_counter() - start
        done.set()
        await asyncio.sleep(0.3)  # late acks
        receiver.cancel()

    print(f"sent {seq} batches in {elapsed:.2f} s ({seq / elapsed:.0f} Hz), {len(server_latency)} acked, {len(errors)} errors")
    print(f"setpoint-to-wire latency (daemon): p50 {percentile(server_latency, 50) / 1000:.2f} ms, "
          f"p99 {percentile(server_latency, 99) / 1000:.2f} ms")
    print(f"client round trip (send -> ack):   p50 {percentile(round_trip, 50) / 1000:.2f} ms, "
          f"p99 {percentile(round_trip, 99) / 1000:.2f} ms")
    print(f"telemetry received: {telemetry / elapsed:.1f} messages/s (subscribed {args.telemetry_hz} Hz)")
    return 0 if server_latency and not errors else 1


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--url", default="ws://127.0.0.1:8080/api/v1/ws")
    p.add_argument("--token", default=None)
    p.add_argument("--enable", action="store_true", help="enable every joint first (they will move!)")
    p.add_argument("--align-s", type=float, default=1.5)
    p.add_argument("--rate-hz", type=float, default=500)
    p.add_argument("--seconds", type=float, default=10)
    p.add_argument("--amplitude", type=float, default=30.0, help="degrees")
    p.add_argument("--freq", type=float, default=0.5, help="sine frequency, Hz")
    p.add_argument("--telemetry-hz", type=float, default=100)
    args = p.parse_args()
    sys.exit(asyncio.run(run(args)))


if __name__ == "__main__":
    main()
