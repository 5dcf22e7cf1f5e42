"""LeRobot's own tools (lerobot-teleoperate, lerobot-record, lerobot-replay)
against two simulated daemons, with this package pip-installed as a user
installs it: found by LeRobot with no import by hand."""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Deque, Dict, List, Tuple


from conftest import JOINTS, WAIT, Daemon, lerobot

FPS = 30
EPISODE_S = 3
# How late the replay may reach a recorded state after the one before it
# (one step of LeRobot's loop held back on a busy host, with room).
STEP_LATE_S = 0.5
# How long a LeRobot tool may take to start (it imports torch: 5-30 s on a
# loaded 2-core host).
TOOL_START_S = 180.0
POSES = [{"index": 40.0, "thumb": -20.0, "ring": 15.0}, {"index": 5.0, "thumb": 10.0, "ring": -10.0}]


class LeaderMotion:
    """Moves the leader hand between two poses until stopped, as a person
    moves a glove (each move starts where the joints are)."""

    def __init__(self, leader: Daemon, duration_ms: float = 700):
        self.leader = leader
        self.duration_ms = duration_ms
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        i = 0
        while not self.stop.is_set():
            self.leader.move(POSES[i % 2], self.duration_ms)
            i += 1
            self.stop.wait(self.duration_ms / 1000 + 0.1)

    def __enter__(self) -> "LeaderMotion":
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()



def streamed_by(follower: Daemon) -> List[Dict]:
    return follower.get("/api/v1/hands")["hands"][0]["streamed_by"]


def finish(proc, timeout: float = 180) -> Tuple[int, str]:
    out, _ = proc.communicate(timeout=timeout)
    return proc.returncode, out


def test_teleoperate_follows_the_leader_and_the_dashboard_says_who_drives(hands, tmp_path):
    leader, follower = hands
    leader.move({"index": 40.0, "thumb": -20.0}, 1500)
    proc = lerobot("teleoperate", ["--teleop_time_s=20", "--display_data=false", "--fps=60"],
                   leader, follower, tmp_path)
    try:
        follower.until(lambda: len(streamed_by(follower)) == 1 or proc.poll() is not None,
                       "the plugin streaming", timeout=TOOL_START_S)
        shown = streamed_by(follower)
        assert shown and shown[0]["name"] == "lerobot-jointd", shown
        assert shown[0]["joints"] == JOINTS
        # The follower goes where the leader went.
        follower.until(lambda: abs(follower.angles()["index"] - 40.0) < 2.0
                       and abs(follower.angles()["thumb"] + 20.0) < 2.0, "the follower at the leader's pose")
    finally:
        rc, out = finish(proc)
    assert rc == 0, out
    assert streamed_by(follower) == [], "the stream ended with the tool"
    # Left as configured: enabled, holding where the leader last was.
    devices = follower.devices()
    assert all(d["state"] == "run" for d in devices.values()), devices
    assert abs(follower.angles()["index"] - 40.0) < 2.0


def test_an_estop_during_teleoperation_leaves_the_follower_stopped(hands, tmp_path):
    leader, follower = hands
    proc = lerobot("teleoperate", ["--teleop_time_s=120", "--display_data=false", "--fps=60"],
                   leader, follower, tmp_path)
    try:
        follower.until(lambda: len(streamed_by(follower)) == 1 or proc.poll() is not None,
                       "the plugin streaming", timeout=TOOL_START_S)
        assert proc.poll() is None, proc.communicate()[0]
        with LeaderMotion(leader):
            follower.call("POST", "/api/v1/estop")
            rc, out = finish(proc, timeout=WAIT)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert rc != 0, "the tool went on after the e-stop"
    assert "the hand was stopped" in out and "connect() again" in out, out[-3000:]
    # Nothing enabled the follower again, and nothing streams to it.
    devices = follower.devices()
    assert all(d["state"] not in ("run", "align") for d in devices.values()), devices
    assert all(d["disabled_reason"] == "estop" for d in devices.values()), devices
    assert streamed_by(follower) == []


def follower_track(follower: Daemon, stop: threading.Event, out: List[Tuple[float, Dict[str, float]]]) -> None:
    while not stop.is_set():
        out.append((time.monotonic(), follower.angles()))
        stop.wait(0.01)


def test_record_two_episodes_load_them_and_replay_one(hands, tmp_path):
    leader, follower = hands
    root = tmp_path / "dataset"
    with LeaderMotion(leader):
        proc = lerobot("record", [
            "--dataset.repo_id=local/jointd-hand", f"--dataset.root={root}", "--dataset.num_episodes=2",
            f"--dataset.episode_time_s={EPISODE_S}", "--dataset.reset_time_s=1", "--dataset.video=false",
            "--dataset.push_to_hub=false", f"--dataset.fps={FPS}", "--dataset.single_task=open and close",
            "--display_data=false", "--play_sounds=false"], leader, follower, tmp_path)
        rc, out = finish(proc)
    assert rc == 0, out[-3000:]

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("local/jointd-hand", root=root)
    assert ds.num_episodes == 2
    names = [f"{j}.pos" for j in JOINTS]
    assert ds.features["action"]["names"] == names
    assert ds.features["observation.state"]["names"] == names
    frames = ds.hf_dataset
    for ep in (0, 1):
        rows = [r for r in frames if int(r["episode_index"]) == ep]
        # Frames in order, one per 1/fps. How many fit in the episode is
        # LeRobot's loop keeping time on this host (a step late is a frame
        # fewer): counted in the benchmark (docs/lerobot.md), not here.
        assert len(rows) >= FPS, len(rows)
        assert [int(r["frame_index"]) for r in rows] == list(range(len(rows)))
        assert all(abs(float(r["timestamp"]) - k / FPS) < 1e-3 for k, r in enumerate(rows))
    ep0 = [r for r in frames if int(r["episode_index"]) == 0]
    actions = [[float(x) for x in r["action"]] for r in ep0]
    states = [[float(x) for x in r["observation.state"]] for r in ep0]
    index = JOINTS.index("index")
    assert max(a[index] for a in actions) - min(a[index] for a in actions) > 10, "the leader moved"

    # Replay from where the episode began, as a user resets the scene.
    follower.move({n: states[0][i] for i, n in enumerate(JOINTS)}, 800)
    follower.until(lambda: all(abs(follower.angles()[n] - states[0][i]) < 1.0 for i, n in enumerate(JOINTS)),
                   "the follower at the episode's start")
    track: List[Tuple[float, Dict[str, float]]] = []
    stop = threading.Event()
    watcher = threading.Thread(target=follower_track, args=(follower, stop, track), daemon=True)
    watcher.start()
    proc = lerobot("replay", ["--dataset.repo_id=local/jointd-hand", f"--dataset.root={root}",
                              "--dataset.episode=0", f"--dataset.fps={FPS}", "--play_sounds=false"],
                   None, follower, tmp_path)
    rc, out = finish(proc)
    stop.set()
    watcher.join()
    assert rc == 0, out[-3000:]
    err = replay_rms(states, track)
    print(f"replay RMS against the recorded follower path: {err:.2f} deg")
    assert err <= 2.0, err


def replay_rms(states: List[List[float]], track: List[Tuple[float, Dict[str, float]]]) -> float:
    """RMS (degrees, over joints and frames) between the follower's recorded
    states and the path it took in the replay: each recorded state matched
    with a point of the watched path, in order and at most `STEP_LATE_S`
    after the previous state's point, the matching that fits best. Where
    the follower went, not when: how late LeRobot's loop ran its steps on
    this host is timing, measured in the benchmark (docs/lerobot.md)."""
    times = [t for t, _ in track]
    points = [[angles[n] for n in JOINTS] for _, angles in track]
    assert points, "the follower was not watched during the replay"

    def dist2(p: List[float], s: List[float]) -> float:
        return sum((a - b) ** 2 for a, b in zip(p, s)) / len(s)

    # cost[j]: the least sum of squares matching the states so far, the
    # last one at point j.
    cost = [dist2(p, states[0]) for p in points]
    for s in states[1:]:
        here = [dist2(p, s) for p in points]
        # The least cost of a previous point at j or before and no more
        # than STEP_LATE_S earlier: a window sliding over the path.
        window: Deque[int] = deque()
        nxt = [math.inf] * len(points)
        for j in range(len(points)):
            while window and cost[window[-1]] >= cost[j]:
                window.pop()
            window.append(j)
            while times[j] - times[window[0]] > STEP_LATE_S:
                window.popleft()
            nxt[j] = here[j] + cost[window[0]]
        cost = nxt
    return math.sqrt(min(cost) / len(states))
