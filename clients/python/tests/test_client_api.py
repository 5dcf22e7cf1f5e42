"""The client as its users meet it: environment defaults, one error
hierarchy for REST and WebSocket, calls that wait until done, and the
operations beyond the first facade (moves, calibration, recordings, frames,
health), against a real daemon on the simulator."""

import asyncio
import socket

import pytest

from jointd_client import (Conflict, Invalid, Jointd, JointdError, NotConnected, NotFound,
                           Unprocessable)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_jointd_url_and_token_come_from_the_environment(daemon, monkeypatch):
    monkeypatch.setenv("JOINTD_URL", daemon.url)
    monkeypatch.setenv("JOINTD_TOKEN", "t0k3n")
    j = Jointd()
    assert (j.url, j.token) == (daemon.url, "t0k3n")
    assert j.buses()[0].name == "sim0"  # a daemon without a token ignores it


def test_a_daemon_not_running_raises_not_connected():
    j = Jointd(f"http://127.0.0.1:{free_port()}", timeout=2)
    with pytest.raises(NotConnected) as e:
        j.buses()
    assert isinstance(e.value, JointdError)

    async def subscribe():
        async for _ in j.telemetry():
            pass

    with pytest.raises(NotConnected):
        asyncio.run(subscribe())


def test_websocket_refusals_raise_the_rest_classes(daemon):
    j = Jointd(daemon.url)

    async def target_a_disabled_joint():
        async with j.setpoints() as s:
            await s.send([{"bus": "sim0", "id": 1, "position_deg": 10}])

    with pytest.raises(Conflict) as e:
        asyncio.run(target_a_disabled_joint())
    assert e.value.status == 409

    async def unknown_device():
        async with j.setpoints() as s:
            await s.send([{"bus": "sim0", "id": 99, "position_deg": 10}])

    with pytest.raises(NotFound):
        asyncio.run(unknown_device())
    # 422 is a kind of invalid input.
    with pytest.raises(Invalid):
        j.target("sim0", 1, position_deg=1e9)
    assert issubclass(Unprocessable, Invalid)


def test_enable_waits_until_the_joint_runs_and_a_move_until_it_ends(daemon):
    j = Jointd(daemon.url)
    j.enable("sim0", 1, wait=True)
    assert next(d for d in j.devices("sim0") if d.id == 1).state == "run"
    move = j.move([{"bus": "sim0", "id": 1, "position_deg": 15}], duration_ms=300, wait=True)
    assert move.state == "done", move.view
    assert [(r["bus"], r["id"]) for r in move.view["arrived"]] == [("sim0", 1)]
    assert j.get_move(move.id)["state"] == "done"
    # A long move stopped midway.
    long = j.move([{"bus": "sim0", "id": 1, "position_deg": -15}], duration_ms=20_000)
    assert long.state == "running"
    assert long.stop()["state"] == "stopped"
    assert long.wait(timeout=5)["state"] == "stopped"
    j.enable_all("sim0", [2, 3], wait=True)
    assert {d.id: d.state for d in j.devices("sim0")}[3] == "run"
    j.disable_all("sim0")


def test_calibration_frames_recordings_and_the_daemon(daemon):
    j = Jointd(daemon.url)
    cal = j.set_calibration("sim0", 2, offset_deg=5.0)
    assert j.calibration("sim0", 2) == cal
    j.clear_calibration("sim0", 2)
    log = j.frames("sim0", limit=5)
    assert 0 < len(log["frames"]) <= 5
    rec = j.start_recording(duration_s=30)
    assert any(r["id"] == rec["id"] for r in j.recordings()["recordings"])
    stopped = j.stop_recording(rec["id"])
    assert j.recording(rec["id"])["id"] == stopped["id"]
    data = j.recording_file(rec["id"])
    assert data[:8] == b"\x89MCAP0\r\n"
    assert j.health()["status"] == "ok"
    assert j.ready()["ready"] is True
    assert "# TYPE jointd_build_info gauge" in j.metrics()
    assert "enabled" in j.ros2()
    assert j.hands()["hands"] == []
    with pytest.raises(NotFound):
        j.pose("left", "open")


def test_the_doctor_reports_on_a_bus_and_is_refused_while_a_joint_is_enabled(daemon):
    j = Jointd(daemon.url)
    j.disable_all("sim0")
    report = j.doctor("sim0")
    assert {d["id"] for d in report["devices"]} >= {1, 2, 3}
    assert "[[bus]]" in report["proposal"]["toml"]
    j.enable("sim0", 1, wait=True)
    with pytest.raises(Conflict):
        j.doctor("sim0")
    j.disable_all("sim0")
