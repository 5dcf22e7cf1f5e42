"""The ROS 2 bridge against a real Zenoh router and real ROS
message definitions, as a ROS 2 node on rmw_zenoh would meet it: a router
in this process (`eclipse-zenoh`, mode router), `jointd --sim 4 --ros2`
connected to it, a client session that subscribes to `joint_states` on the
key expression rmw_zenoh derives (domain, topic, DDS type name, the type
hash `rosbags` computes from the definition) and decodes with `rosbags`;
it publishes `joint_commands` and the simulated joint moves, a bad command
is dropped whole, `/diagnostics` decodes, and the liveliness tokens parse
as rmw_zenoh's. Needs a jointd built with `--features ros2` (CI's is)."""

import contextlib
import json
import socket
import struct
import subprocess
import time
import urllib.request

import pytest
import zenoh
from rosbags.typesys import Stores, get_typestore

from conftest import Daemon

TS = get_typestore(Stores.ROS2_JAZZY)
JOINT_STATE = "sensor_msgs/msg/JointState"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"


def dds_name(ros_type):
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def key(topic, ros_type, domain=0):
    return f"{domain}/{topic.strip('/')}/{dds_name(ros_type)}/{TS.hash_rihs01(ros_type)}"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def zenoh_config(mode, endpoints_key, endpoint):
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5(endpoints_key, json.dumps([endpoint]))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


def call(base, method, path, body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read() or b"null")


@contextlib.contextmanager
def on_router(joints, daemon_args):
    """A Zenoh router, `jointd` started with `daemon_args(endpoint)`, and a
    Zenoh client of the router: yields (daemon, client) once `joints`
    simulated joints are online; closes all three after."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(zenoh_config("router", "listen/endpoints", endpoint))
    try:
        d = Daemon(*daemon_args(endpoint))
        client = zenoh.open(zenoh_config("client", "connect/endpoints", endpoint))
        try:
            online = f'"devices_online":{joints}'.encode()
            d.wait("/api/v1/buses/sim0", lambda b: online in b, f"{joints} joints online")
            yield d, client
        finally:
            client.close()
            d.stop()
    finally:
        router.close()


@pytest.fixture()
def ros2():
    with on_router(4, lambda endpoint: ["--sim", "4", "--ros2", "--ros2-connect", endpoint]) as pair:
        yield pair


def wait_for(what, ok, timeout=15.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = ok()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def test_joint_states_commands_diagnostics_and_tokens(ros2):
    d, client = ros2
    api = d.url + "/api/v1"
    assert call(api, "GET", "/ros2")["enabled"] is True, "built with --features ros2?"

    states, diagnostics = [], []
    client.declare_subscriber(key("/sim0/joint_states", JOINT_STATE),
                              lambda s: states.append((bytes(s.payload.to_bytes()),
                                                       bytes(s.attachment.to_bytes()))))
    client.declare_subscriber(key("/diagnostics", DIAGNOSTICS),
                              lambda s: diagnostics.append(bytes(s.payload.to_bytes())))
    wait_for("joint states and diagnostics", lambda: len(states) > 50 and diagnostics)

    msg = TS.deserialize_cdr(states[-1][0], JOINT_STATE)
    assert list(msg.name) == ["sim0_1", "sim0_2", "sim0_3", "sim0_4"]
    assert len(msg.position) == len(msg.velocity) == len(msg.effort) == 4
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9
    assert abs(stamp - time.time()) < 5, "stamped with the sample's time"
    sequences = []
    for _, attachment in states[-10:]:
        assert len(attachment) == 33
        seq, source_ns, gid_len = struct.unpack("<qqB", attachment[:17])
        assert gid_len == 16 and abs(source_ns / 1e9 - time.time()) < 5
        sequences.append(seq)
    assert sequences == sorted(sequences) and len(set(sequences)) == 10

    diag = TS.deserialize_cdr(diagnostics[-1], DIAGNOSTICS)
    names = [s.name for s in diag.status]
    assert names == ["jointd: bus sim0"] + [f"jointd: sim0_{i}" for i in range(1, 5)], names
    values = {kv.key: kv.value for kv in diag.status[1].values}
    assert {"state", "fault", "temperature_c", "voltage_v", "online"} <= values.keys(), values
    assert values["online"] == "true"

    # Commands: enabled joints follow; a command naming an unknown joint is
    # dropped whole (joint 1 in it does not move), and counted.
    call(api, "POST", "/buses/sim0/control/enable", {"ids": [1, 2, 3, 4]})
    wait_for("joints running", lambda: all(
        dev["state"] == "run" for dev in call(api, "GET", "/buses/sim0/devices")["devices"]))
    publisher = client.declare_publisher(key("/sim0/joint_commands", JOINT_STATE))
    Time = TS.types["builtin_interfaces/msg/Time"]
    Header = TS.types["std_msgs/msg/Header"]
    Cmd = TS.types[JOINT_STATE]
    import numpy as np

    def command(names, rad):
        m = Cmd(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), name=names,
                position=np.array(rad, dtype=np.float64), velocity=np.array([], dtype=np.float64),
                effort=np.array([], dtype=np.float64))
        return bytes(TS.serialize_cdr(m, JOINT_STATE))

    publisher.put(command(["sim0_1", "pinky"], [0.5, 0.1]))
    wait_for("the bad command counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= 1)
    status = call(api, "GET", "/ros2")
    assert "pinky" in status["last_dropped"], status
    publisher.put(command(["sim0_2"], [0.5]))  # 28.65 degrees
    view = wait_for("joint 2 at 0.5 rad", lambda: (lambda v: v if abs(v["motion"]["angle_deg"] - 28.648) < 0.5 else None)(
        call(api, "GET", "/buses/sim0/devices/2")))
    assert view["target"]["position_deg"] == pytest.approx(28.648, abs=0.01)
    assert abs(call(api, "GET", "/buses/sim0/devices/1")["motion"]["angle_deg"]) < 0.5, "nothing of the bad one"
    assert call(api, "GET", "/ros2")["commands_applied"] >= 1
    # Outside the joint's soft limit (±255 deg at most): dropped, not clamped.
    publisher.put(command(["sim0_3"], [10.0]))
    wait_for("the out-of-range command counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= 2)
    assert abs(call(api, "GET", "/buses/sim0/devices/3")["motion"]["angle_deg"]) < 0.5

    # After an e-stop a command is refused whole: no joint moves that
    # nobody enabled since (the motion authority, as for REST and WebSocket).
    call(api, "POST", "/estop")
    dropped = call(api, "GET", "/ros2")["commands_dropped"]
    publisher.put(command(["sim0_2"], [-0.5]))
    wait_for("the command after the e-stop counted",
             lambda: call(api, "GET", "/ros2")["commands_dropped"] > dropped)
    assert "not enabled" in call(api, "GET", "/ros2")["last_dropped"]
    assert call(api, "GET", "/buses/sim0/devices/2")["target"] is None

    # The graph as rmw_zenoh's graph cache reads it.
    tokens = [str(r.ok.key_expr) for r in client.liveliness().get("@ros2_lv/**")]
    parts = [t.split("/") for t in tokens]
    node = [p for p in parts if p[5] == "NN"]
    assert len(node) == 1 and node[0][:2] == ["@ros2_lv", "0"] and node[0][6:] == ["%", "%", "jointd"], tokens
    zid = node[0][2]
    endpoints = {(p[5], p[9]): p for p in parts if p[5] in ("MP", "MS")}
    types = {("MP", "%sim0%joint_states"): JOINT_STATE, ("MS", "%sim0%joint_commands"): JOINT_STATE,
             ("MS", "%sim0%joint_trajectory"): "trajectory_msgs/msg/JointTrajectory",
             ("MP", "%diagnostics"): DIAGNOSTICS, ("MP", "%rosout"): "rcl_interfaces/msg/Log"}
    assert set(endpoints) == set(types), tokens
    for (kind, topic), p in endpoints.items():
        assert len(p) == 13 and p[2] == zid and p[3] == "0", p
        ros_type = types[(kind, topic)]
        assert p[10] == dds_name(ros_type) and p[11] == TS.hash_rihs01(ros_type), p
        assert len(p[12].split(":")) == 6, p[12]
    assert len({p[4] for p in endpoints.values()}) == len(types), "an entity id each"


def test_a_namespace_per_hand(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(zenoh_config("router", "listen/endpoints", endpoint))
    config = tmp_path / "jointd.toml"
    config.write_text(f"""
[[hand]]
name = "left"
joints = [{{ bus = "sim0", ids = "2-3", names = ["index", "middle"] }}]

[ros2]
enabled = true
namespace_by = "hand"
joint_states_max_hz = 20.0
connect = ["{endpoint}"]
""")
    d = Daemon("--sim", "4", "--config", str(config))
    client = zenoh.open(zenoh_config("client", "connect/endpoints", endpoint))
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":4' in b, "4 joints online")
        api = d.url + "/api/v1"
        states = []
        client.declare_subscriber(key("/left/joint_states", JOINT_STATE),
                                  lambda s: states.append(bytes(s.payload.to_bytes())))
        wait_for("the hand's joint states", lambda: len(states) > 10)
        # Capped at 20/s (the bus polls each joint ~250 times a second).
        before = len(states)
        time.sleep(2.0)
        assert 0 < len(states) - before <= 2 * 20 + 2, len(states) - before
        msg = TS.deserialize_cdr(states[-1], JOINT_STATE)
        assert list(msg.name) == ["index", "middle"] and msg.header.frame_id == "left"
        call(api, "POST", "/buses/sim0/control/enable", {"ids": [2, 3]})
        wait_for("joints running", lambda: all(
            call(api, "GET", f"/buses/sim0/devices/{i}")["status"]["state"] == "run" for i in (2, 3)))
        Cmd, Header, Time = (TS.types[t] for t in (JOINT_STATE, "std_msgs/msg/Header",
                                                    "builtin_interfaces/msg/Time"))
        import numpy as np
        cmd = Cmd(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), name=["middle"],
                  position=np.array([-0.3]), velocity=np.array([], dtype=np.float64),
                  effort=np.array([], dtype=np.float64))
        client.declare_publisher(key("/left/joint_commands", JOINT_STATE)).put(
            bytes(TS.serialize_cdr(cmd, JOINT_STATE)))
        wait_for("joint 3 at -0.3 rad", lambda: abs(
            call(api, "GET", "/buses/sim0/devices/3")["motion"]["angle_deg"] + 17.19) < 0.5)
        tokens = [str(r.ok.key_expr) for r in client.liveliness().get("@ros2_lv/**")]
        assert any("/MP/%/%/jointd/%left%joint_states/" in t for t in tokens), tokens
        assert not any("%sim0%" in t for t in tokens), "per hand, not per bus"
    finally:
        client.close()
        d.stop()
        router.close()
