"""What the plugin costs a LeRobot control loop, against a running daemon:
`get_observation()` time and the age of what it returns, `send_action()`
to the frame on the wire, missed steps of a fixed-rate loop, and the CPU
the plugin takes; optionally a `lerobot-record` run counting its frames.

    python3 clients/lerobot/bench.py --url http://127.0.0.1:8080 --hand right --seconds 60
    python3 clients/lerobot/bench.py ... --record-leader http://127.0.0.1:8081

Numbers and how they were measured: docs/lerobot.md.
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import subprocess
import sys
import tempfile
import time
from typing import List

from lerobot_robot_jointd import Jointd, JointdConfig


def pct(xs: List[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


def row(name: str, xs: List[float], unit: str = "ms") -> str:
    return (f"{name:<34} p50 {pct(xs, 0.5):7.3f}  p99 {pct(xs, 0.99):7.3f}  "
            f"max {max(xs) if xs else float('nan'):7.3f} {unit}  (n={len(xs)})")


def loop(args: argparse.Namespace) -> None:
    cal = pathlib.Path(tempfile.mkdtemp(prefix="jointd-bench-"))
    robot = Jointd(JointdConfig(url=args.url, hand=args.hand, id="bench", calibration_dir=cal,
                                measure_latency=True, telemetry_hz=args.telemetry_hz))
    robot.connect()
    names = robot.joint_names
    # The WebSocket's round trip bounds the plugin-to-daemon leg of an
    # action (the ack's own trip back waits for the daemon's next
    # snapshot, so it is no measure of it).
    link = robot._link
    assert link is not None
    rtts: List[float] = []
    for _ in range(500):
        t = time.perf_counter()
        link.call({"type": "ping"}, "pong", 2.0)
        rtts.append((time.perf_counter() - t) * 1e3)
    period = 1.0 / args.hz
    obs_ms: List[float] = []
    ages: List[float] = []
    send_ms: List[float] = []
    missed_by_plugin = overruns = steps = 0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    next_t = wall0
    try:
        while time.perf_counter() - wall0 < args.seconds:
            t0 = time.perf_counter()
            obs = robot.get_observation()
            t1 = time.perf_counter()
            ages.append(robot.observation_age_ms())
            phase = 2 * math.pi * 0.5 * (t1 - wall0)
            action = {f"{n}.pos": 20.0 * math.sin(phase) for n in names}
            t2 = time.perf_counter()
            robot.send_action(action)
            t3 = time.perf_counter()
            obs_ms.append((t1 - t0) * 1e3)
            send_ms.append((t3 - t2) * 1e3)
            steps += 1
            if (t1 - t0) + (t3 - t2) > period:
                missed_by_plugin += 1
            next_t += period
            left = next_t - time.perf_counter()
            if left > 0:
                time.sleep(left)
            else:
                overruns += 1
                next_t = time.perf_counter()
            assert obs, "an observation"
    finally:
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        time.sleep(0.2)
        lat = robot.latencies()
        robot.disconnect()
    print(f"{steps} steps at {args.hz:g} Hz in {wall:.1f} s, {len(names)} joints, telemetry {args.telemetry_hz:g} Hz")
    print(row("get_observation()", obs_ms))
    print(row("observation age", ages))
    print(row("send_action() call", send_ms))
    print(row("WebSocket round trip (ping)", rtts))
    print(row("daemon: accepted -> on the wire", [w for _, w in lat]))
    # Per action: its call (the socket write included), plus the daemon's
    # accepted -> on the wire, plus the worst round trip seen (a bound of
    # the socket's one way).
    worst_rtt = max(rtts)
    print(row("send_action() -> on the wire (bound)", [c + w + worst_rtt for c, (_, w) in zip(send_ms, lat)]))
    print(f"steps the plugin made late: {missed_by_plugin}; loop overruns (any cause): {overruns}")
    print(f"CPU of this process (plugin + a trivial loop): {100 * cpu / wall:.1f} % of a core")


def record(args: argparse.Namespace) -> None:
    root = pathlib.Path(tempfile.mkdtemp(prefix="jointd-bench-ds-")) / "ds"
    tool = pathlib.Path(sys.executable).parent / "lerobot-record"
    cmd = [str(tool), "--robot.type=jointd", f"--robot.url={args.url}", f"--robot.hand={args.hand}",
           "--robot.id=bench", "--teleop.type=jointd_leader", f"--teleop.url={args.record_leader}",
           f"--teleop.hand={args.leader_hand or args.hand}", "--teleop.id=bench-leader",
           "--dataset.repo_id=local/jointd-bench", f"--dataset.root={root}", "--dataset.num_episodes=1",
           f"--dataset.episode_time_s={args.seconds:g}", "--dataset.reset_time_s=0",
           "--dataset.video=false", "--dataset.push_to_hub=false", "--dataset.fps=30",
           "--dataset.single_task=bench", "--display_data=false", "--play_sounds=false"]
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    ds = LeRobotDataset("local/jointd-bench", root=root)
    want = int(round(30 * args.seconds))
    print(f"lerobot-record at 30 fps for {args.seconds:g} s: {ds.num_frames} frames of {want}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--url", default=os.environ.get("JOINTD_URL", "http://127.0.0.1:8080"))
    p.add_argument("--hand", required=True)
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--hz", type=float, default=100.0)
    p.add_argument("--telemetry-hz", type=float, default=200.0)
    p.add_argument("--record-leader", help="a leader daemon's URL: run lerobot-record instead")
    p.add_argument("--leader-hand")
    args = p.parse_args()
    if args.record_leader:
        record(args)
    else:
        loop(args)


if __name__ == "__main__":
    main()
