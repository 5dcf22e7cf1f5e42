"""Grasping through the client, against a daemon whose simulator has an
object before finger `a` and none before `c`: `grasp(..., wait=True)`
returns once a holds it (contact near the object, holding at the set
current) and c found nothing; `release()` opens both and restores every
limit; a second grasp is stopped; bad grasps raise the daemon's problem."""

import time

import pytest

from conftest import Daemon
from jointd_client import Conflict, Grasp, Jointd, NotFound, Timeout, Unprocessable

HOLD_A = 0.2
HAND = """
[[hand]]
name = "h"
joints = [{ bus = "sim0", ids = "1-3", names = ["a", "b", "c"] }]
"""


@pytest.fixture()
def hand(tmp_path):
    """A daemon with hand `h` of joints 1..3, an object at 12° before joint
    1 (0.05 N·m/°), every joint enabled and running."""
    config = tmp_path / "jointd.toml"
    config.write_text(HAND)
    d = Daemon("--sim", "3", "--sim-object", "1=12:0.05", "--config", str(config),
               "--state-dir", str(tmp_path))
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":3' in b, "3 joints online")
        j = Jointd(d.url)
        j.enable_all("sim0", wait=True)
        yield j
    finally:
        d.stop()


FINGERS = [{"joint": "a", "close_to_deg": 40.0}, {"joint": "c", "close_to_deg": 20.0}]


def test_a_grasp_closes_holds_and_lets_go(hand):
    j = hand
    g = j.grasp("h", speed_dps=30.0, hold_current_a=HOLD_A, joints=FINGERS, wait=True,
                timeout=20)
    assert isinstance(g, Grasp) and g.state == "running", g.view
    assert [f["joint"] for f in g.fingers] == ["a", "c"]
    a, c = g.finger("a"), g.finger("c")
    assert a["state"] == "holding" and a["contact"] is True, a
    assert 10.0 <= (a.get("contact_deg") or 0.0) <= 14.0, a
    assert c["state"] == "no_contact" and c["contact"] is False and c.get("contact_deg") is None, c
    # The reported current comes up to the hold setting while it presses.
    deadline = time.monotonic() + 10
    while abs((g.finger("a").get("q_current_a") or 0.0) - HOLD_A) > 0.1 * HOLD_A:
        assert time.monotonic() < deadline, g.view
        time.sleep(0.02)
        g.refresh()
    # The handle's view is the daemon's (the currents move between reads).
    def settled(v):
        return (v["id"], v["state"], [(f["joint"], f["state"], f["contact"], f.get("contact_deg"))
                                      for f in v["fingers"]])
    assert settled(g.view) == settled(j.get_grasp(g.id))

    done = g.release()
    assert done["state"] == "done" and g.state == "done"
    for f in g.fingers:
        assert f["state"] == "released" and f["current_limit_restored"] is True, f
    assert j.config("sim0", 1)["max_current_a"]["value"] == pytest.approx(
        g.finger("a").get("previous_current_limit_a"), abs=1e-3)
    # It ended: releasing again is a conflict naming it, waiting returns.
    with pytest.raises(Conflict) as e:
        g.release()
    assert "ended" in e.value.problem.detail
    assert g.wait(until="done", timeout=5)["state"] == "done"


def test_a_grasp_is_stopped_and_bad_grasps_say_why(hand):
    j = hand
    # Joint a has no range of its own: without a closing limit it is refused.
    with pytest.raises(Unprocessable) as e:
        j.grasp("h", 20.0, HOLD_A, joints=["a"])
    assert e.value.problem.field == "joints.a.close_to_deg", e.value.problem
    g = j.grasp("h", 20.0, HOLD_A, joints=[{"joint": "a", "close_to_deg": 30.0},
                                           {"joint": "b", "close_to_deg": 30.0}])
    with pytest.raises(Conflict):
        j.grasp("h", 20.0, HOLD_A, joints=["a"])
    with pytest.raises(Timeout):
        g.wait(timeout=0.05)
    view = g.stop()
    assert view["state"] == "done"
    assert {f["state"] for f in view["fingers"]} == {"stopped"}, view
    assert all(f["current_limit_restored"] for f in view["fingers"]), view
    assert j.stop_grasp(g.id) == view

    with pytest.raises(Unprocessable) as e:
        j.grasp("h", speed_dps=0.0, hold_current_a=HOLD_A)
    assert e.value.problem.field == "speed_dps"
    with pytest.raises(Unprocessable) as e:
        j.grasp("h", 30.0, HOLD_A, joints=["z"])
    assert "`z`" in (e.value.problem.detail or "")
    with pytest.raises(NotFound):
        j.grasp("nope", 30.0, HOLD_A)
    with pytest.raises(NotFound):
        j.get_grasp(99)
    with pytest.raises(NotFound):
        g.finger("z")
