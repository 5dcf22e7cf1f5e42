#!/usr/bin/env python3
"""Does the daemon's memory come back after many WebSocket clients leave? (issue 13)

Starts `jointd --sim 16` on a free port, reads its resident memory (VmRSS in
/proc/PID/status) once the simulator is up and idle, then runs CYCLES rounds
of: CLIENTS connections, each subscribing to all 16 joints at RATE Hz and
reading for STREAM seconds (peak RSS taken while they all stream), all closed,
SETTLE seconds of quiet, RSS again. A leak grows cycle after cycle; allocator
retention stays at one plateau.

Usage: scripts/ws-memory.py [--bin target/release/jointd] [--clients 500]
       [--cycles 3] [--rate 100] [--stream 5] [--settle 5] [--warmup 60] [--probe]
Needs Python 3.11+ and `pip install websockets`. Raises its own open-file limit.
"""

import argparse
import asyncio
import json
import os
import re
import resource
import socket
import subprocess
import sys
import time

import websockets


def rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("no VmRSS")


def fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def gdb_probe(pid: int, log: str) -> str:
    """glibc's own account, from inside the daemon (gdb attached for a moment):
    bytes still allocated (a leak keeps them), then what malloc_trim(0) gives
    back (retention: freed memory glibc kept)."""
    start = os.path.getsize(log)
    before = rss_kib(pid)
    subprocess.run(
        ["gdb", "-p", str(pid), "-batch", "-ex", "call (void)malloc_stats()",
         "-ex", "call (int)malloc_trim(0)"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True,
    )
    with open(log) as f:
        f.seek(start)
        stats = f.read()
    in_use = re.findall(r"in use bytes\s*=\s*(\d+)", stats)
    arenas = stats.count("Arena ")
    used = f"{int(in_use[-1]) / 2**20:.1f} MiB in use" if in_use else "in use ?"
    return f"malloc: {arenas} arenas, {used}; malloc_trim(0): {mib(before)} -> {mib(rss_kib(pid))}"


def mib(kib: int) -> str:
    return f"{kib / 1024:.1f} MiB"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def client(url: str, rate: int, stop: asyncio.Event, counts: list):
    async with websockets.connect(url, max_queue=64, open_timeout=30) as ws:
        await ws.recv()  # welcome
        sub = {"type": "subscribe", "seq": 1, "rate_hz": rate}
        await ws.send(json.dumps(sub))
        n = 0
        while not stop.is_set():
            try:
                await asyncio.wait_for(ws.recv(), 0.5)
                n += 1
            except asyncio.TimeoutError:
                pass
        counts.append(n)


async def cycle(url: str, pid: int, args) -> tuple[int, int]:
    stop = asyncio.Event()
    counts: list[int] = []
    tasks = []
    for i in range(args.clients):
        tasks.append(asyncio.create_task(client(url, args.rate, stop, counts)))
        if i % 50 == 49:  # connect in batches of 50
            await asyncio.sleep(0.05)
    await asyncio.sleep(args.stream)
    peak = rss_kib(pid)
    stop.set()
    results = await asyncio.gather(*tasks, return_exceptions=True)
    errors = [r for r in results if isinstance(r, BaseException)]
    if errors:
        print(f"  {len(errors)} clients failed, first: {errors[0]!r}", file=sys.stderr)
    streamed = sum(counts) / max(1, len(counts)) / args.stream
    print(f"  {len(counts)} clients streamed ~{streamed:.0f} msgs/s each")
    return peak, len(errors)


async def main_async(args) -> int:
    port = free_port()
    log = f"/tmp/ws-memory-{port}.log"
    proc = subprocess.Popen(
        [args.bin, "--sim", "16", "--listen", f"127.0.0.1:{port}"],
        stdout=subprocess.DEVNULL,
        stderr=open(log, "w"),
    )
    try:
        url = f"ws://127.0.0.1:{port}/api/v1/ws"
        for _ in range(100):  # wait for the listener
            try:
                socket.create_connection(("127.0.0.1", port), 0.2).close()
                break
            except OSError:
                await asyncio.sleep(0.1)
        await asyncio.sleep(args.settle)  # simulator up, joints found, idle
        print(f"after {args.settle:.0f} s {mib(rss_kib(proc.pid))}")
        # The simulator's bounded rings (frame log, delivery samples: ~9 MiB
        # when full) fill in the first minute: the baseline is taken after.
        await asyncio.sleep(args.warmup)
        base = rss_kib(proc.pid)
        print(f"baseline (after {args.warmup:.0f} s more) {mib(base)}, {fds(proc.pid)} open files")
        if args.probe:
            print("  " + gdb_probe(proc.pid, log))
        for c in range(1, args.cycles + 1):
            peak, _ = await cycle(url, proc.pid, args)
            await asyncio.sleep(args.settle)
            after = rss_kib(proc.pid)
            print(
                f"cycle {c}: peak {mib(peak)}, after leave {mib(after)} "
                f"({after / base:.2f}x baseline), {fds(proc.pid)} open files"
            )
            if args.probe:
                print("  " + gdb_probe(proc.pid, log))
        return 0
    finally:
        proc.terminate()
        proc.wait(10)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin", default="target/release/jointd")
    p.add_argument("--clients", type=int, default=500)
    p.add_argument("--cycles", type=int, default=3)
    p.add_argument("--rate", type=int, default=100)
    p.add_argument("--stream", type=float, default=5.0)
    p.add_argument("--settle", type=float, default=5.0)
    p.add_argument("--warmup", type=float, default=60.0)
    p.add_argument("--probe", action="store_true",
                   help="after each cycle: malloc_stats() and malloc_trim(0) via gdb (changes later cycles)")
    args = p.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = min(hard, max(soft, 4 * args.clients + 256))
    resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    return asyncio.run(main_async(args))


if __name__ == "__main__":
    sys.exit(main())
