#!/usr/bin/env python3
"""E-stop latency with and without a flood of other work (docs/safety.md).

Starts `jointd --sim 16` on a free port (recordings under a temporary state
dir), waits for the 16 joints, then for each run:

1. quiet: E-STOPS e-stops one after another, nothing else going on;
2. flood: 4 recordings, WS clients subscribed to telemetry (100 Hz), and
   CONCURRENCY HTTP clients sending mixed GETs and POSTs back to back on
   keep-alive connections, then E-STOPS e-stops while it all runs;
3. (last run, with --sigterm) SIGTERM during the flood: how long until the
   process exits, and whether its log says the joints were disabled.

Each e-stop is sent by a separate process (blocking socket, a new TCP
connection each time, as a panic button would), so the flood's own event
loop does not delay it. Two numbers per e-stop: `latency_us` from the
daemon's answer (the call -> the first disable frame handed to the port)
and the wall time of the HTTP call as the client saw it.

Usage: scripts/estop-flood.py [--bin target/release/jointd] [--runs 3]
       [--concurrency 1000] [--ws 100] [--estops 20] [--sigterm]
Needs Python 3.11+ and `pip install websockets`. Every loop is bounded in
count and time, and only 127.0.0.1 is contacted. Raises its own open-file
limit (the daemon inherits it).
"""

import argparse
import asyncio
import json
import os
import resource
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time

import websockets

HOST = "127.0.0.1"
JOINTS = 16
GETS = ["/api/v1/buses", "/api/v1/buses/sim0/devices", "/api/v1/recordings",
        "/metrics", "/readyz", "/api/v1/buses/sim0/devices/3"]
POSTS = [("POST", "/api/v1/buses/sim0/control/disable", b"{}"),
         ("POST", "/api/v1/buses/sim0/devices/2/disable", b""),
         ("POST", "/api/v1/recordings", b"{}"),
         ("PUT", "/api/v1/buses/sim0/control/mode", b'{"mode":"position"}')]


def free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def blocking_request(port, method, path, body=b"", timeout=60.0):
    """One request on a new connection; (status, body bytes, seconds)."""
    t0 = time.perf_counter()
    with socket.create_connection((HOST, port), timeout=timeout) as s:
        head = (f"{method} {path} HTTP/1.1\r\nHost: {HOST}:{port}\r\n"
                f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
                "Connection: close\r\n\r\n").encode()
        s.sendall(head + body)
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    wall = time.perf_counter() - t0
    head, _, rest = data.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1])
    if b"transfer-encoding: chunked" in head.lower():
        out = b""
        while rest:
            size, _, rest = rest.partition(b"\r\n")
            n = int(size, 16)
            if n == 0:
                break
            out, rest = out + rest[:n], rest[n + 2:]
        rest = out
    return status, rest, wall


def probe(port: int, count: int, gap: float) -> None:
    """The e-stop client: COUNT e-stops GAP s apart, one JSON line each."""
    for _ in range(count):
        try:
            status, body, wall = blocking_request(port, "POST", "/api/v1/estop", timeout=60)
            r = json.loads(body)
            if status != 200:
                r = r.get("partial") or {}
            buses = r.get("buses") or [{}]
            print(json.dumps({"status": status, "wall_us": int(wall * 1e6),
                              "latency_us": buses[0].get("latency_us"),
                              "frames_sent": buses[0].get("frames_sent")}), flush=True)
        except Exception as e:  # a timeout is a result too
            print(json.dumps({"status": None, "error": repr(e)}), flush=True)
        time.sleep(gap)


def run_probe(args, port):
    out = subprocess.run(
        [sys.executable, __file__, "--probe", str(port), "--estops", str(args.estops),
         "--gap", str(args.gap)],
        capture_output=True, text=True, timeout=args.estops * 70 + 30)
    return [json.loads(line) for line in out.stdout.splitlines() if line.strip()]


async def http_client(port, i, stop, counts):
    """Mixed requests back to back on one keep-alive connection."""
    n = i
    reader = writer = None
    while not stop.is_set():
        try:
            if writer is None:
                reader, writer = await asyncio.open_connection(HOST, port)
            n += 1
            if n % 2:
                method, path, body = "GET", GETS[n // 2 % len(GETS)], b""
            else:
                method, path, body = POSTS[n // 2 % len(POSTS)]
            writer.write((f"{method} {path} HTTP/1.1\r\nHost: {HOST}:{port}\r\n"
                          f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n"
                          ).encode() + body)
            await writer.drain()
            status_line = await asyncio.wait_for(reader.readline(), 60)
            if not status_line:
                raise ConnectionError("closed")
            status = int(status_line.split()[1])
            length, chunked = 0, False
            while (line := await reader.readline()) not in (b"\r\n", b""):
                k, _, v = line.decode().partition(":")
                if k.lower() == "content-length":
                    length = int(v)
                elif k.lower() == "transfer-encoding" and "chunked" in v:
                    chunked = True
            if chunked:
                while True:
                    size = int((await reader.readline()).strip() or b"0", 16)
                    await reader.readexactly(size + 2)
                    if size == 0:
                        break
                body = b""
            else:
                body = await reader.readexactly(length)
            # A shed request (503 overloaded) apart from a busy bus's 503.
            key = "503 overloaded" if status == 503 and b"overloaded" in body else status
            counts[key] = counts.get(key, 0) + 1
        except Exception:
            counts["error"] = counts.get("error", 0) + 1
            if writer is not None:
                writer.close()
            reader = writer = None
            await asyncio.sleep(0.05)
    if writer is not None:
        writer.close()


async def ws_client(port, stop, counts):
    try:
        async with websockets.connect(f"ws://{HOST}:{port}/api/v1/ws", max_queue=64,
                                      open_timeout=60) as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "subscribe", "seq": 1, "rate_hz": 100}))
            while not stop.is_set():
                try:
                    await asyncio.wait_for(ws.recv(), 0.5)
                    counts["ws_msgs"] = counts.get("ws_msgs", 0) + 1
                except asyncio.TimeoutError:
                    pass
    except Exception:
        counts["ws_error"] = counts.get("ws_error", 0) + 1


async def flood(args, port, proc, log_path):
    stop = asyncio.Event()
    counts: dict = {}
    recs = [blocking_request(port, "POST", "/api/v1/recordings", b"{}")[0] for _ in range(4)]
    tasks = [asyncio.create_task(ws_client(port, stop, counts)) for _ in range(args.ws)]
    for i in range(args.concurrency):
        tasks.append(asyncio.create_task(http_client(port, i, stop, counts)))
        if i % 100 == 99:
            await asyncio.sleep(0.01)
    t0 = time.monotonic()
    while sum(v for k, v in counts.items() if isinstance(k, int)) < args.concurrency:
        await asyncio.sleep(0.05)
        if time.monotonic() - t0 > 60:
            break
    result = {"recordings": recs}
    result["estops"] = await asyncio.to_thread(run_probe, args, port)
    # What the flood was answered while the daemon served it.
    result["answers"] = dict(counts)
    if args.sigterm_now:
        t1 = time.perf_counter()
        proc.send_signal(signal.SIGTERM)
        try:
            await asyncio.to_thread(proc.wait, 60)
            result["sigterm_exit_s"] = time.perf_counter() - t1
        except subprocess.TimeoutExpired:
            result["sigterm_exit_s"] = None
        with open(log_path) as f:
            result["disabled"] = "shutdown: disable sent to every joint" in f.read()
    stop.set()
    await asyncio.gather(*tasks, return_exceptions=True)
    if not args.sigterm_now:
        for r in json.loads(blocking_request(port, "GET", "/api/v1/recordings")[1])["recordings"]:
            if r["state"] == "recording":
                blocking_request(port, "DELETE", f"/api/v1/recordings/{r['id']}")
    return result


def pct(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(p / 100 * (len(xs) - 1))))]


def summary(name, estops):
    ok = [e for e in estops if e.get("status") == 200]
    failed = len(estops) - len(ok)
    lat = [e["latency_us"] for e in ok if e.get("latency_us") is not None]
    wall = [e["wall_us"] for e in ok]
    line = f"{name}: {len(ok)}/{len(estops)} answered 200"
    if failed:
        line += f" ({failed} not: {[e.get('status') or e.get('error') for e in estops if e not in ok][:3]})"
    if lat:
        line += (f"; latency_us p50 {pct(lat, 50)} p99 {pct(lat, 99)} max {max(lat)}"
                 f"; wall ms p50 {pct(wall, 50) / 1e3:.1f} p99 {pct(wall, 99) / 1e3:.1f}"
                 f" max {max(wall) / 1e3:.1f}")
    return line


def start_daemon(args, port, state_dir, log_path):
    proc = subprocess.Popen(
        [args.bin, "--sim", str(JOINTS), "--listen", f"{HOST}:{port}", "--state-dir", state_dir],
        stdout=subprocess.DEVNULL, stderr=open(log_path, "w"))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            status, body, _ = blocking_request(port, "GET", "/api/v1/buses/sim0/devices", timeout=2)
            if status == 200 and sum(d["online"] for d in json.loads(body)["devices"]) == JOINTS:
                return proc
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.1)
    proc.kill()
    raise SystemExit("jointd did not bring its joints online in 60 s")


async def main_async(args) -> int:
    quiet_all, flood_all, exits = [], [], []
    for run in range(1, args.runs + 1):
        port = free_port()
        state_dir = tempfile.mkdtemp(prefix="jointd-flood-")
        log_path = os.path.join(state_dir, "jointd.log")
        proc = start_daemon(args, port, state_dir, log_path)
        try:
            quiet = await asyncio.to_thread(run_probe, args, port)
            args.sigterm_now = args.sigterm
            flooded = await flood(args, port, proc, log_path)
        finally:
            if proc.poll() is None:
                proc.terminate()
                proc.wait(30)
        quiet_all += quiet
        flood_all += flooded["estops"]
        print(f"run {run}: recordings started {flooded['recordings']}, flood answers "
              f"{dict(sorted(flooded['answers'].items(), key=str))}")
        print("  " + summary("quiet", quiet))
        print("  " + summary("flood", flooded["estops"]))
        if args.sigterm:
            exits.append(flooded["sigterm_exit_s"])
            print(f"  SIGTERM during the flood: exited after "
                  f"{flooded['sigterm_exit_s'] if flooded['sigterm_exit_s'] is None else round(flooded['sigterm_exit_s'], 2)} s, "
                  f"joints disabled in the log: {flooded['disabled']}")
    print(f"all {args.runs} runs:")
    print("  " + summary("quiet", quiet_all))
    print("  " + summary("flood", flood_all))
    if exits:
        done = [e for e in exits if e is not None]
        print(f"  SIGTERM to exit, s: {', '.join(f'{e:.2f}' for e in done)}"
              f"{'' if len(done) == len(exits) else f' ({len(exits) - len(done)} did not exit in 60 s)'}")
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin", default="target/release/jointd")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--concurrency", type=int, default=1000)
    p.add_argument("--ws", type=int, default=100)
    p.add_argument("--estops", type=int, default=20)
    p.add_argument("--gap", type=float, default=0.25, help="s between e-stops")
    p.add_argument("--sigterm", action="store_true",
                   help="end each run's flood with SIGTERM and time the exit")
    p.add_argument("--probe", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.probe:
        probe(args.probe, args.estops, args.gap)
        return 0
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = min(hard, max(soft, 2 * (args.concurrency + args.ws) + 512))
    resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    return asyncio.run(main_async(args))


if __name__ == "__main__":
    sys.exit(main())
