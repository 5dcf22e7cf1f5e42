"""Every facade call against a real daemon on the simulator, and one error
path per kind (404, 409, 422, 503)."""

import time

import pytest

from jointd_client import Conflict, Jointd, NotFound, Unavailable, Unprocessable


def wait_state(j, bus, dev_id, state, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        d = next(d for d in j.devices(bus) if d.id == dev_id)
        if d.state == state:
            return d
        time.sleep(0.05)
    raise AssertionError(f"device {dev_id} never reached {state}")


def test_buses_devices_and_the_device_view(daemon):
    j = Jointd(daemon.url)
    buses = j.buses()
    assert [b.name for b in buses] == ["sim0"] and buses[0].link == "up"
    assert j.bus("sim0").devices_online == 4
    devices = j.devices("sim0")
    assert [d.id for d in devices] == [1, 2, 3, 4] and all(d.online for d in devices)
    assert j.device("sim0", 2, fresh=True)["id"] == 2
    assert any(p["key"] == "pos_kp" for p in j.params())
    assert j.scan("sim0", 1, 6) == [1, 2, 3, 4]


def test_enable_target_mode_disable_move_the_simulated_joint(daemon):
    j = Jointd(daemon.url)
    done = j.enable("sim0", 1)
    assert (done.action, done.ids) == ("enable", [1])
    wait_state(j, "sim0", 1, "run")
    ack = j.target("sim0", 1, position_deg=20, speed_dps=200)
    assert ack.targets[0]["position_deg"] == 20
    deadline = time.monotonic() + 20
    while abs((next(d for d in j.devices("sim0") if d.id == 1).angle_deg or 0) - 20) > 1:
        assert time.monotonic() < deadline, "joint 1 never reached 20 degrees"
        time.sleep(0.05)
    assert j.set_mode("sim0", 1, "position").value == "position"
    assert j.disable("sim0", 1).action == "disable"
    assert j.enable_all("sim0", [2, 3]).ids == [2, 3]
    assert j.disable_all("sim0").action == "disable"


def test_config_read_write_persist(daemon):
    j = Jointd(daemon.url)
    before = j.config("sim0", 1)["pos_kp"]["value"]
    wanted = 0.5 if before != 0.5 else 0.75
    written = j.set_config("sim0", 1, pos_kp=wanted)
    assert written["written"][0]["param"] == "pos_kp"
    assert j.config("sim0", 1)["pos_kp"]["value"] == wanted
    assert j.persist("sim0", 1)["persisted"] is True


def test_estop_all_and_one_bus(daemon):
    j = Jointd(daemon.url)
    j.enable("sim0", 2)
    assert j.estop()["stopped"] is True
    assert j.estop("sim0")["stopped"] is True
    wait_state(j, "sim0", 2, "ready")


def test_errors_carry_the_problem(daemon, down_daemon):
    j = Jointd(daemon.url)
    with pytest.raises(NotFound) as e:
        j.enable("sim0", 99)
    assert e.value.status == 404 and e.value.type.endswith("unknown-device")
    with pytest.raises(Conflict) as e:
        j.target("sim0", 3, position_deg=10)  # not enabled
    assert e.value.status == 409 and "enable" in e.value.detail
    j.enable("sim0", 4)
    with pytest.raises(Unprocessable) as e:
        j.target("sim0", 4, position_deg=300)
    assert e.value.status == 422 and e.value.field == "position_deg"
    with pytest.raises(Unavailable) as e:
        Jointd(down_daemon.url).enable("gone", 1)
    assert e.value.status == 503 and e.value.type.endswith("bus-down")


def test_a_token_is_sent():
    from conftest import Daemon

    d = Daemon("--sim", "1", "--token", "s3cret")
    try:
        with pytest.raises(Exception) as e:
            Jointd(d.url).buses()
        assert getattr(e.value, "status", None) == 401
        assert Jointd(d.url, token="s3cret").buses()[0].name == "sim0"
    finally:
        d.stop()
