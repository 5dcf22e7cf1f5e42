"""Telemetry and setpoints over the WebSocket against the simulator."""

import asyncio
import json
import time

from jointd_client import Jointd

JOINTS = "/api/v1/buses/sim0/devices"


def joint_1(body):
    return next(d for d in json.loads(body)["devices"] if d["id"] == 1)


def test_telemetry_yields_samples_of_the_asked_devices(daemon):
    j = Jointd(daemon.url)

    async def take(n):
        got = []
        async for sample in j.telemetry(devices=[1, 2], rate_hz=50):
            got.append(sample)
            if len(got) == n:
                break
        return got

    samples = asyncio.run(take(5))
    seqs = [s.seq for s in samples]
    assert seqs == sorted(seqs) and len(set(seqs)) == 5
    assert {jt["id"] for jt in samples[-1].joints} == {1, 2}


def test_setpoints_are_acked_move_the_joint_and_end_without_a_watchdog_firing(daemon):
    j = Jointd(daemon.url)
    j.enable("sim0", 1)
    daemon.wait(JOINTS, lambda b: joint_1(b)["state"] == "run", "joint 1 to finish aligning")

    async def stream():
        acks = []
        # A long hold: the point is the clean end, not the timer (a loaded
        # 2-core CI machine can pause a client for 200 ms).
        async with j.setpoints(hold_timeout_ms=2000) as s:
            for k in range(20):
                acks.append(await s.send([{"bus": "sim0", "id": 1, "position_deg": k, "speed_dps": 200}]))
                await asyncio.sleep(0.01)
        return acks

    acks = asyncio.run(stream())
    assert len(acks) == 20 and all(a["type"] == "ack" and a["latency_us"] >= 0 for a in acks)
    daemon.wait(JOINTS, lambda b: abs(joint_1(b)["angle_deg"] - 19) < 2, "joint 1 at the last target, 19°")
    # Disarmed, then closed: the daemon saw a client that finished, not one
    # that vanished mid-stream.
    time.sleep(0.3)
    log = daemon.log_text()
    assert "watchdog fired" not in log, log


def test_enable_disable_and_estop_over_the_stream_are_the_daemons(daemon):
    j = Jointd(daemon.url)

    def state(i):
        return next(d for d in j.devices("sim0") if d.id == i).state

    def wait(what, ok):
        deadline = time.monotonic() + 20
        while not ok():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            time.sleep(0.05)

    async def session():
        async with j.setpoints(hold_timeout_ms=2000) as s:
            done = await s.enable("sim0", [1, 2])
            assert (done["type"], done["action"], done["ids"]) == ("done", "enable", [1, 2]), done
            wait("joints 1 and 2 running", lambda: state(1) == "run" and state(2) == "run")
            try:
                await s.enable("sim0", [99])
            except Exception as e:  # the core's refusal, as REST says it
                refused = str(e)
            else:
                raise AssertionError("an unknown device was enabled")
            assert "99" in refused, refused
            off = await s.disable("sim0", [2])
            assert off["action"] == "disable", off
            wait("joint 2 disabled", lambda: state(2) != "run")
            return await s.estop("sim0")

    result = asyncio.run(session())
    assert result["stopped"] is True, result
    assert state(1) != "run"
