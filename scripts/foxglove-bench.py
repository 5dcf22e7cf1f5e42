#!/usr/bin/env python3
"""Does a Foxglove client slow the bus or the WebSocket clients?

Starts `jointd --sim 16 --foxglove 127.0.0.1:0` and measures, in phases
that alternate (none, a live client, a stalled client; each `--seconds`,
`--rounds` times), the bus's wire occupancy (its `wire_busy_us` counter
over the phase), its replies per second (telemetry), and the rate a jointd
WebSocket telemetry subscriber (100 Hz) receives. The live client
subscribes to every channel and reads everything; the stalled one
subscribes to every channel and never reads (4 KB receive buffer), so its
queue in the daemon fills. Prints each phase and the ratios to `none`.

    python3 scripts/foxglove-bench.py --bin target/release/jointd

Needs Python's `websockets` (the Python client's venv has it).
"""

import argparse
import asyncio
import json
import re
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"


def get(url):
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def counters(api):
    c = get(api + "/buses/sim0")["counters"]
    return time.monotonic(), c["wire_busy_us"], c["frames_rx"]


class Foxglove:
    """A Foxglove protocol client: every advertised channel subscribed."""

    def __init__(self, url, stalled):
        self.url, self.stalled, self.messages, self.task = url, stalled, 0, None

    async def start(self):
        host, port = self.url.removeprefix("ws://").rsplit(":", 1)
        sock = socket.socket()
        if self.stalled:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((host, int(port)))
        # max_queue=1: a client that does not read stops reading the socket.
        self.ws = await websockets.connect(self.url, sock=sock, subprotocols=[SUBPROTOCOL],
                                           max_queue=1 if self.stalled else None, max_size=None)
        channels = []
        while True:
            msg = json.loads(await asyncio.wait_for(self.ws.recv(), 10))
            if msg.get("op") == "advertise":
                channels += msg["channels"]
                break
        subs = [{"id": i, "channelId": ch["id"]} for i, ch in enumerate(channels)]
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        if not self.stalled:
            self.task = asyncio.create_task(self.read())

    async def read(self):
        async for msg in self.ws:
            if isinstance(msg, bytes):
                self.messages += 1

    async def stop(self):
        if self.task:
            self.task.cancel()
        self.ws.transport.abort()


class Telemetry:
    """A jointd WebSocket client subscribed to every joint at 100 Hz."""

    def __init__(self, url):
        self.url, self.messages = url, 0

    async def run(self):
        async with websockets.connect(self.url, max_size=None) as ws:
            await ws.send(json.dumps({"type": "subscribe", "seq": 1, "rate_hz": 100}))
            async for raw in ws:
                if json.loads(raw).get("type") == "telemetry":
                    self.messages += 1


async def phase(kind, api, fox_url, telemetry, seconds):
    client = None
    if kind != "none":
        client = Foxglove(fox_url, stalled=(kind == "stalled"))
        await client.start()
        await asyncio.sleep(1.0)  # the stalled client's queue fills first
    t0, busy0, rx0 = await asyncio.to_thread(counters, api)
    ws0 = telemetry.messages
    fox0 = client.messages if client else 0
    await asyncio.sleep(seconds)
    t1, busy1, rx1 = await asyncio.to_thread(counters, api)
    dt = t1 - t0
    row = {
        "phase": kind,
        "occupancy": (busy1 - busy0) / (dt * 1e6),
        "replies_per_s": (rx1 - rx0) / dt,
        "ws_telemetry_hz": (telemetry.messages - ws0) / dt,
        "foxglove_msgs_per_s": ((client.messages - fox0) / dt) if client else 0.0,
    }
    if client:
        await client.stop()
    return row


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/jointd")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    log = tempfile.NamedTemporaryFile("w+", suffix=".log")
    proc = subprocess.Popen([args.bin, "--sim", "16", "--foxglove", "127.0.0.1:0",
                             "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        base = proc.stdout.readline().split()[-1]
        api = base + "/api/v1"
        deadline = time.monotonic() + 20
        fox_url = None
        while fox_url is None:
            assert time.monotonic() < deadline, "no Foxglove url in the log"
            log.seek(0)
            m = re.search(r"ws://127\.0\.0\.1:\d+", log.read())
            fox_url = m.group(0) if m else None
            time.sleep(0.1)
        while get(api + "/buses/sim0")["devices_online"] < 16:
            time.sleep(0.1)
        telemetry = Telemetry(base.replace("http://", "ws://") + "/api/v1/ws")
        tel_task = asyncio.create_task(telemetry.run())
        await asyncio.sleep(2.0)
        rows = []
        for _ in range(args.rounds):
            for kind in ("none", "live", "stalled"):
                row = await phase(kind, api, fox_url, telemetry, args.seconds)
                rows.append(row)
                print(json.dumps(row), flush=True)
        tel_task.cancel()
        print("\nphase    occupancy  ratio   replies/s  ratio   ws Hz   ratio   foxglove msgs/s")
        none = [r for r in rows if r["phase"] == "none"]
        ref = {k: sum(r[k] for r in none) / len(none) for k in ("occupancy", "replies_per_s", "ws_telemetry_hz")}
        for kind in ("none", "live", "stalled"):
            rs = [r for r in rows if r["phase"] == kind]
            avg = {k: sum(r[k] for r in rs) / len(rs) for k in rs[0] if k != "phase"}
            print(f"{kind:8} {avg['occupancy']:.4f}   {avg['occupancy'] / ref['occupancy']:.4f}  "
                  f"{avg['replies_per_s']:8.1f}   {avg['replies_per_s'] / ref['replies_per_s']:.4f}  "
                  f"{avg['ws_telemetry_hz']:6.1f}  {avg['ws_telemetry_hz'] / ref['ws_telemetry_hz']:.4f}  "
                  f"{avg['foxglove_msgs_per_s']:8.1f}")
    finally:
        proc.terminate()
        proc.wait(10)


if __name__ == "__main__":
    sys.exit(asyncio.run(main()))
