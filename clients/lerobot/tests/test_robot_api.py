"""The robot and the teleoperator as a LeRobot script calls them, against
simulated daemons: errors a user can act on, clipping, what disconnect
leaves, and a policy process killed mid-stream."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from lerobot.utils.errors import DeviceNotConnectedError
from websockets.sync.client import connect

from conftest import HAND, JOINTS, STALE_AFTER_MS, Daemon
from lerobot_robot_jointd import HandStopped, Jointd, JointdConfig, JointdLeader, JointdLeaderConfig


def robot(follower: Daemon, tmp_path, **kw) -> Jointd:
    return Jointd(JointdConfig(url=follower.url, hand=HAND, id="follower", calibration_dir=tmp_path / "cal",
                               stale_after_ms=STALE_AFTER_MS, **kw))


def test_a_daemon_down_or_a_hand_unknown_is_a_clear_error(hands, tmp_path):
    _, follower = hands
    down = Jointd(JointdConfig(url="http://127.0.0.1:9", hand=HAND, id="x", calibration_dir=tmp_path))
    with pytest.raises(DeviceNotConnectedError, match="not reachable at http://127.0.0.1:9"):
        down.connect()
    unknown = Jointd(JointdConfig(url=follower.url, hand="left", id="x", calibration_dir=tmp_path))
    with pytest.raises(DeviceNotConnectedError, match="no hand `left`; its hands: right"):
        unknown.connect()
    r = robot(follower, tmp_path)
    with pytest.raises(DeviceNotConnectedError):
        r.get_observation()
    # Nothing was enabled by the attempts.
    assert all(d["state"] == "ready" for d in follower.devices().values())


def test_features_name_the_hands_joints_and_calibration_mirrors_the_daemon(hands, tmp_path):
    _, follower = hands
    follower.call("PUT", "/api/v1/buses/sim0/devices/3/calibration",
                  {"offset_deg": 10.0, "flip": True, "range_deg": [0.0, 90.0]})
    r = robot(follower, tmp_path, observe_velocity=True)
    assert list(r.action_features) == [f"{j}.pos" for j in JOINTS]
    assert "index.vel" in r.observation_features
    assert not r.is_calibrated
    r.calibrate()
    assert r.is_calibrated
    assert (r.calibration["index"].drive_mode, r.calibration["index"].homing_offset,
            r.calibration["index"].range_min, r.calibration["index"].range_max) == (1, 1000, 0, 9000)
    follower.call("PUT", "/api/v1/buses/sim0/devices/3/calibration", {"offset_deg": 12.0})
    assert not r.is_calibrated, "the file no longer says what the daemon says"


def test_actions_are_clipped_from_where_the_joint_is_and_disconnect_can_disable(hands, tmp_path):
    _, follower = hands
    r = robot(follower, tmp_path, max_relative_target=5.0, disable_on_disconnect=True)
    r.connect()
    try:
        assert all(d["state"] == "run" for d in follower.devices().values()), "connect() enabled the hand"
        sent = r.send_action({"index.pos": 50.0})
        assert sent["index.pos"] == pytest.approx(5.0, abs=0.5)
        follower.until(lambda: abs(follower.angles()["index"] - sent["index.pos"]) < 0.5, "index at the clip")
        # The robot's observation comes from its own telemetry stream, a little after REST's.
        follower.until(
            lambda: abs(r.get_observation()["index.pos"] - sent["index.pos"]) < 0.5, "the robot sees index at the clip"
        )
        # Beyond the ring's soft limit (30°, tests/conftest.py): sent at the limit, and said
        # (clipped from where the robot sees the ring, so it waits to see it there).
        follower.move({"ring": 28.0}, 300)
        follower.until(lambda: abs(r.get_observation()["ring.pos"] - 28.0) < 0.5, "the robot sees ring near its limit")
        assert r.send_action({"ring.pos": 31.0})["ring.pos"] == 30.0
        with pytest.raises(ValueError, match="no joint"):
            r.send_action({"pinky.pos": 1.0})
    finally:
        r.disconnect()
    assert all(d["state"] != "run" for d in follower.devices().values()), "disable_on_disconnect"


def test_after_a_disable_the_robot_refuses_until_connect_enables_again(hands, tmp_path):
    _, follower = hands
    r = robot(follower, tmp_path)
    r.connect()
    r.send_action({"index.pos": 3.0})
    follower.call("POST", "/api/v1/buses/sim0/devices/3/disable")
    follower.until(lambda: follower.devices()[3]["state"] != "run", "index disabled")
    # The daemon says at once that the stream ended; the robot raises from then on.
    with pytest.raises(HandStopped, match="connect\\(\\) again"):
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            r.send_action({"index.pos": 4.0})
            time.sleep(0.01)
    assert follower.devices()[3]["state"] != "run", "the plugin enabled it again"
    r.disconnect()
    r.connect()
    assert follower.devices()[3]["state"] == "run"
    r.send_action({"index.pos": 6.0})
    follower.until(lambda: abs(follower.angles()["index"] - 6.0) < 0.5, "index driven again")
    r.disconnect()


def test_a_hand_stopped_and_enabled_again_before_the_first_action_is_not_driven(hands, tmp_path):
    _, follower = hands
    r = robot(follower, tmp_path)
    r.connect()
    follower.call("POST", "/api/v1/estop")
    follower.until(lambda: all(d["state"] != "run" for d in follower.devices().values()), "e-stopped")
    # Someone at the dashboard enables the hand again before the policy's first action.
    follower.enable_all()
    before = follower.angles()["index"]
    with pytest.raises(HandStopped, match="estop|e-stop"):
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            r.send_action({"index.pos": before + 20.0})
            time.sleep(0.01)
    assert abs(follower.angles()["index"] - before) < 0.5, "this connection drove the joint"
    r.disconnect()


def test_a_killed_policy_process_leaves_the_hand_held(hands, tmp_path):
    _, follower = hands
    script = textwrap.dedent(f"""
        import math, pathlib, time
        from lerobot_robot_jointd import Jointd, JointdConfig
        r = Jointd(JointdConfig(url={follower.url!r}, hand={HAND!r}, id="policy",
                                calibration_dir=pathlib.Path({str(tmp_path / 'cal')!r}), hold_timeout_ms=200))
        r.connect()
        print("streaming", flush=True)
        t0 = time.monotonic()
        while True:
            r.send_action({{"index.pos": 30.0 * math.sin(time.monotonic() - t0)}})
            time.sleep(0.01)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    ws_url = follower.url.replace("http://", "ws://") + "/api/v1/ws"
    with connect(ws_url) as watcher:
        try:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "streaming"
            follower.until(lambda: abs(follower.angles()["index"]) > 5.0, "the policy moving the index")
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        finally:
            if proc.poll() is None:
                proc.kill()
        # The connection closed with the watchdog armed: every client hears it fire. A policy process held back
        # for 200 ms on a busy host has already let it fire on a timeout, which holds the hand too; the close
        # fires it again.
        deadline = time.monotonic() + 10
        while True:
            msg = json.loads(watcher.recv(timeout=max(0.1, deadline - time.monotonic())))
            ev = msg.get("event") or {}
            if msg.get("type") != "event" or ev.get("event") != "watchdog":
                continue
            if ev["why"] != "timeout":
                break
            assert ev["policy"] == "hold", ev
        assert (ev["policy"], ev["why"]) == ("hold", "closed"), ev
        assert {"bus": "sim0", "id": 3} in ev["joints"], ev
    # Each joint is held where it is (its target its measured angle), still enabled.
    follower.until(lambda: follower.get("/api/v1/hands")["hands"][0]["streamed_by"] == [], "the stream gone")
    follower.until(lambda: held(follower), "the index held")
    assert follower.devices()[3]["state"] == "run"


def held(follower: Daemon) -> bool:
    d = follower.get("/api/v1/buses/sim0/devices/3")
    return (d["target"] is not None and d["motion"]["speed_dps"] is not None
            and abs(d["motion"]["speed_dps"]) < 1.0
            and abs(d["target"]["position_deg"] - d["motion"]["angle_deg"]) < 1.0)


def test_the_leader_reads_and_maps_names_and_never_enables(hands, tmp_path):
    leader, _ = hands
    leader.call("POST", "/api/v1/buses/sim0/control/disable", {})
    leader.until(lambda: all(d["state"] != "run" for d in leader.devices().values()), "leader disabled")
    t = JointdLeader(JointdLeaderConfig(url=leader.url, hand=HAND, id="leader", calibration_dir=tmp_path,
                                        joint_map={"index": "pointer"}))
    assert "pointer.pos" in t.action_features and "index.pos" not in t.action_features
    t.connect()
    action = t.get_action()
    assert set(action) == {f"{j}.pos" for j in ["thumb_rot", "thumb", "pointer", "middle", "ring", "little"]}
    t.disconnect()
    assert all(d["state"] != "run" for d in leader.devices().values())
