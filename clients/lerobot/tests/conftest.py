"""Two real daemons on the simulator, a leader hand and a follower hand,
each `target/debug/jointd` (or $JOINTD_BIN) on a free port; LeRobot's own
command-line tools run against them as a user runs them."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time
import urllib.request
from typing import Any, Callable, Dict, List, Optional

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("JOINTD_BIN", str(ROOT / "target" / "debug" / "jointd"))
BINDIR = pathlib.Path(sys.executable).parent
HAND = "right"
JOINTS = ["thumb_rot", "thumb", "index", "middle", "ring", "little"]
CONFIG = f"""[[hand]]
name = "{HAND}"
joints = [{{ bus = "sim0", ids = "1-6", names = {json.dumps(JOINTS)} }}]

[[limit]]
ids = [5]
min_deg = -30.0
max_deg = 30.0
"""
WAIT = 30.0
# Samples a loaded CI host (two debug daemons, LeRobot and busy loops on 2
# cores) may leave older than the default 1 s without anything being wrong
# with the plugin: what these tests judge is not the host's speed.
STALE_AFTER_MS = 5000


class Daemon:
    """`jointd --sim 6` with one hand of 6 joints."""

    def __init__(self, tmp: pathlib.Path, name: str):
        config = tmp / f"{name}.toml"
        config.write_text(CONFIG)
        self.log = tempfile.NamedTemporaryFile("w+", prefix=f"jointd-{name}-", suffix=".log")
        self.proc = subprocess.Popen([BIN, "--sim", "6", "--config", str(config), "--listen", "127.0.0.1:0"],
                                     stdout=subprocess.PIPE, stderr=self.log, text=True,
                                     env={**os.environ, "NO_COLOR": "1", "TMPDIR": str(tmp)})
        first = self.proc.stdout.readline() if self.proc.stdout else ""
        assert first.startswith("listening on "), f"no address line: {first!r}"
        self.url = first.split()[-1]
        self.until(lambda: self.get("/api/v1/buses/sim0")["devices_online"] == 6, "6 joints online")

    def call(self, method: str, path: str, body: Any = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, method=method, data=data,
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=10) as r:
            text = r.read()
            return json.loads(text) if text else None

    def get(self, path: str) -> Any:
        return self.call("GET", path)

    def devices(self) -> Dict[int, Dict[str, Any]]:
        return {d["id"]: d for d in self.get("/api/v1/buses/sim0/devices")["devices"]}

    def angles(self) -> Dict[str, float]:
        by_id = self.devices()
        return {name: by_id[i + 1]["angle_deg"] for i, name in enumerate(JOINTS)}

    def until(self, ok: Callable[[], bool], what: str, timeout: float = WAIT) -> None:
        deadline = time.monotonic() + timeout
        while not ok():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            time.sleep(0.05)

    def enable_all(self) -> None:
        self.call("POST", "/api/v1/buses/sim0/control/enable", {})
        self.until(lambda: all(d["state"] == "run" for d in self.devices().values()), "joints running")

    def move(self, positions: Dict[str, float], duration_ms: float) -> int:
        joints = [{"hand": HAND, "joint": n, "position_deg": p} for n, p in positions.items()]
        return self.call("POST", "/api/v1/moves", {"joints": joints, "duration_ms": duration_ms})["id"]

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()


@pytest.fixture()
def hands(tmp_path: pathlib.Path):
    """(leader, follower): two daemons, the leader's joints enabled so the
    test can move them as a person moves a glove."""
    leader = Daemon(tmp_path, "leader")
    follower = Daemon(tmp_path, "follower")
    leader.enable_all()
    yield leader, follower
    leader.stop()
    follower.stop()


def lerobot(tool: str, args: List[str], leader: Optional[Daemon], follower: Daemon,
            tmp: pathlib.Path) -> subprocess.Popen:
    """Starts `lerobot-<tool>` with the follower robot (and the leader
    teleoperator); calibration files under `tmp`."""
    cmd = [str(BINDIR / f"lerobot-{tool}"), "--robot.type=jointd", f"--robot.url={follower.url}",
           f"--robot.hand={HAND}", "--robot.id=follower", f"--robot.calibration_dir={tmp / 'cal'}",
           f"--robot.stale_after_ms={STALE_AFTER_MS}"]
    if leader is not None:
        cmd += ["--teleop.type=jointd_leader", f"--teleop.url={leader.url}", f"--teleop.hand={HAND}",
                "--teleop.id=leader", f"--teleop.calibration_dir={tmp / 'cal'}",
                f"--teleop.stale_after_ms={STALE_AFTER_MS}"]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(tmp / "hf")}
    return subprocess.Popen(cmd + args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=tmp)
