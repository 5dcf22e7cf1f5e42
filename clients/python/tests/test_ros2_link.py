"""The ROS 2 bridge without a router: the daemon serves its buses and API
regardless, `GET /api/v1/ros2` and `/metrics` say it is not connected, and
once a router listens where it points the bridge connects by itself (its
retries back off from 0.5 s) and joint states flow; a router that goes away
and comes back is the same again. Needs a jointd built with
`--features ros2` (CI's is)."""

import urllib.request

import zenoh

from conftest import Daemon
from test_ros2 import JOINT_STATE, call, free_port, key, wait_for, zenoh_config


def metric(base, name):
    with urllib.request.urlopen(base + "/metrics", timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line.startswith(name + " "):
                return float(line.split()[1])
    raise AssertionError(f"{name} not in /metrics")


def test_no_router_then_a_router_then_none_then_one_again():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    d = Daemon("--sim", "4", "--ros2", "--ros2-connect", endpoint)
    router = client = None
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":4' in b, "4 joints online")
        api = d.url + "/api/v1"
        assert len(call(api, "GET", "/buses")) >= 1
        status = wait_for("a failed attempt reported",
                          lambda: (lambda s: s if s["last_error"] else None)(call(api, "GET", "/ros2")))
        assert status["enabled"] is True and status["connected"] is False, status
        assert status["connects"] == 0, status
        assert metric(d.url, "jointd_ros2_connected") == 0

        router = zenoh.open(zenoh_config("router", "listen/endpoints", endpoint))
        wait_for("the bridge connected", lambda: call(api, "GET", "/ros2")["connected"], timeout=45)
        assert metric(d.url, "jointd_ros2_connected") == 1
        client = zenoh.open(zenoh_config("client", "connect/endpoints", endpoint))
        states = []
        client.declare_subscriber(key("/sim0/joint_states", JOINT_STATE),
                                  lambda s: states.append(1))
        wait_for("joint states through the router", lambda: len(states) > 10)

        # The router goes: said once, counted, and the daemon serves on.
        client.close()
        client = None
        router.close()
        router = None
        wait_for("the loss seen", lambda: not call(api, "GET", "/ros2")["connected"])
        assert metric(d.url, "jointd_ros2_connected") == 0
        assert call(api, "GET", "/buses/sim0")["devices_online"] == 4
        router = zenoh.open(zenoh_config("router", "listen/endpoints", endpoint))
        status = wait_for("connected again", lambda: (lambda s: s if s["connected"] else None)(
            call(api, "GET", "/ros2")), timeout=45)
        assert status["connects"] == 2, status

        log = d.log_text()
        assert log.count("no Zenoh router reachable") == 1, log
        assert log.count("the Zenoh router went away") == 1, log
        assert log.count("ROS 2 bridge connected") == 2, log
    finally:
        if client is not None:
            client.close()
        d.stop()
        if router is not None:
            router.close()
