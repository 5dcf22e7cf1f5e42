#!/usr/bin/env python3
"""The ROS 2 bridge under load (issue 16): `jointd --sim 16` twice, without
and with `--ros2`, behind a Zenoh router run here; with the bridge, one
subscriber on `/sim0/joint_states`. Reports the message rate, the latency
from a sample's wire time (the message's header stamp) to the subscriber,
the daemon's CPU (whole process, from /proc), and the bus's own figures
(polls/s, wire occupancy, telemetry Hz per joint) with and without the
bridge, as a ratio.

    python3 scripts/ros2-bench.py [--bin target/release/jointd] [--seconds 10]

Needs `pip install eclipse-zenoh rosbags` and a jointd built with
`--features ros2`. Same host clock on both ends: the latency is real.
"""

import argparse
import json
import os
import socket
import statistics
import subprocess
import threading
import time
import urllib.request

import zenoh
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
JS = "sensor_msgs/msg/JointState"
KEY = f"0/sim0/joint_states/sensor_msgs::msg::dds_::JointState_/{TS.hash_rihs01(JS)}"
TICKS = os.sysconf("SC_CLK_TCK")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config(mode, key, endpoint):
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5(key, json.dumps([endpoint]))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


def get(base, path):
    with urllib.request.urlopen(base + path, timeout=5) as r:
        return json.loads(r.read())


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def run(binary, seconds, bridge, endpoint):
    args = [binary, "--sim", "16", "--listen", "127.0.0.1:0"]
    if bridge:
        args += ["--ros2", "--ros2-connect", endpoint]
    d = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    base = d.stdout.readline().split()[-1]
    try:
        deadline = time.time() + 20
        while get(base, "/api/v1/buses/sim0")["devices_online"] < 16:
            assert time.time() < deadline, "joints never online"
            time.sleep(0.1)
        latencies, count = [], [0]
        lock = threading.Lock()
        client = sub = None
        if bridge:
            client = zenoh.open(config("client", "connect/endpoints", endpoint))

            def on_sample(sample):
                now = time.time()
                m = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), JS)
                with lock:
                    count[0] += 1
                    latencies.append(now - (m.header.stamp.sec + m.header.stamp.nanosec / 1e9))

            sub = client.declare_subscriber(KEY, on_sample)
        time.sleep(2.0)  # warm-up: rates settle, the subscriber is matched
        with lock:
            count[0], latencies[:] = 0, []
        c0, t0 = cpu_s(d.pid), time.time()
        samples = []
        while time.time() - t0 < seconds:
            time.sleep(1.0)
            bus = get(base, "/api/v1/buses/sim0")
            devs = get(base, "/api/v1/buses/sim0/devices")["devices"]
            samples.append((bus["rates"]["polls_per_s"], bus["rates"]["wire_utilisation"],
                            statistics.mean(x["telemetry_hz"] for x in devs)))
        wall = time.time() - t0
        cpu = (cpu_s(d.pid) - c0) / wall
        with lock:
            n, lat = count[0], sorted(latencies)
        if sub is not None:
            sub.undeclare()
            client.close()
        out = {
            "polls_per_s": statistics.mean(s[0] for s in samples),
            "occupancy": statistics.mean(s[1] for s in samples),
            "telemetry_hz_per_joint": statistics.mean(s[2] for s in samples),
            "daemon_cpu": cpu,
        }
        if bridge:
            out["msgs_per_s"] = n / wall
            out["latency_ms_p50"] = 1e3 * lat[len(lat) // 2] if lat else None
            out["latency_ms_p99"] = 1e3 * lat[int(len(lat) * 0.99)] if lat else None
            out["ros2"] = get(base, "/api/v1/ros2")
        return out
    finally:
        d.terminate()
        d.wait(10)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default="target/release/jointd")
    p.add_argument("--seconds", type=float, default=10.0)
    a = p.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(config("router", "listen/endpoints", endpoint))
    try:
        without = run(a.bin, a.seconds, False, endpoint)
        with_bridge = run(a.bin, a.seconds, True, endpoint)
    finally:
        router.close()
    ratios = {k: with_bridge[k] / without[k] for k in ("polls_per_s", "occupancy", "telemetry_hz_per_joint")}
    print(json.dumps({"without": without, "with": with_bridge, "with/without": ratios}, indent=2))
    ok = all(abs(r - 1) <= 0.05 for r in ratios.values())
    print(f"bus figures within 5 % of running without the bridge: {'yes' if ok else 'NO'}")


if __name__ == "__main__":
    main()
