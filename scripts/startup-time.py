#!/usr/bin/env python3
"""How soon `jointd --sim 16` is usable, timed from the process start (the
README's start-up figures).

Each run starts the binary on a free port and polls its API every
millisecond: the `listening on` line, `GET /api/v1/buses` answering, the
16 simulated joints online, then (once every joint's state has been read)
joint 1 enabled until its state is `run` (it aligns its encoder first),
then sent to 45 deg at 30 deg/s until it reads past 44.5 deg, as the
README's walkthrough does. Prints one line per run, milliseconds from the
start, then each figure's range.

Usage: scripts/startup-time.py [--bin target/release/jointd] [--runs 5]
Standard library only; only 127.0.0.1 is contacted.
"""

import argparse
import json
import subprocess
import time
import urllib.request

FIGURES = ["listening_line", "buses_answer", "online_16", "runs", "at_45_deg"]


def get(url):
    with urllib.request.urlopen(url, timeout=2) as r:
        return json.loads(r.read())


def send(method, url, body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method,
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=5) as r:
        r.read()


def until(pred, within=30.0):
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            if pred():
                return time.monotonic()
        except OSError:
            pass  # not listening yet, or a request cut short: ask again
        time.sleep(0.001)
    raise SystemExit("timed out")


def one_run(binary):
    t0 = time.monotonic()
    proc = subprocess.Popen([binary, "--sim", "16", "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        t = {"listening_line": time.monotonic()}
        if not line.startswith("listening on "):
            raise SystemExit(f"no address line: {line!r}")
        api = line.split()[-1] + "/api/v1"
        t["buses_answer"] = until(lambda: get(api + "/buses") is not None)
        t["online_16"] = until(lambda: get(api + "/buses/sim0")["devices_online"] == 16)
        until(lambda: all(d.get("state") for d in get(api + "/buses/sim0/devices")["devices"]))
        dev = api + "/buses/sim0/devices/1"
        send("POST", dev + "/enable")
        t["runs"] = until(lambda: get(dev)["status"]["state"] == "run")
        send("PUT", dev + "/target", {"position_deg": 45, "speed_dps": 30})
        t["at_45_deg"] = until(lambda: get(dev)["motion"]["angle_deg"] > 44.5)
        return {k: round((t[k] - t0) * 1000) for k in FIGURES}
    finally:
        proc.terminate()
        proc.wait(10)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin", default="target/release/jointd")
    p.add_argument("--runs", type=int, default=5)
    args = p.parse_args()
    runs = []
    for _ in range(args.runs):
        runs.append(one_run(args.bin))
        print(json.dumps(runs[-1]), flush=True)
        time.sleep(1.0)
    for k in FIGURES:
        values = [r[k] for r in runs]
        print(f"{k}: {min(values)}-{max(values)} ms")


if __name__ == "__main__":
    main()
