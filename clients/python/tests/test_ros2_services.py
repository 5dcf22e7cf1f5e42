"""The ROS 2 bridge's services, trajectories, /rosout and per-bus
diagnostics, as a ROS 2 node on rmw_zenoh meets them: a service call is a
Zenoh query on the key rmw_zenoh derives for the service (its type hash
computed here from the service's description, as REP-2016 defines it)
with the CDR request and rmw_zenoh's attachment; the reply carries the
CDR response and the request's sequence number and client GID. The joints'
state is read back through REST. Needs a jointd built with `--features
ros2` (CI's is)."""

import json
import struct
import time
import urllib.error

import numpy as np
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.base import Nodetype

from test_ros2 import DIAGNOSTICS, TS, call, dds_name, key, on_router, ros2, wait_for  # noqa: F401 (fixture)

LOG = "rcl_interfaces/msg/Log"
TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
GID = bytes(range(16))


def _srv_path(value):
    """rosbags files `pkg/srv/Name_Request` under `pkg/srv/msg/`: undo it."""
    if isinstance(value, str):
        return value.replace("/srv/msg/", "/srv/")
    if isinstance(value, (tuple, list)):
        return type(value)(_srv_path(v) for v in value)
    return value


def service_hash(name, request, response):
    """RIHS01 of a service: the hash of the struct of its request, response
    and event messages (REP-2016), `char[16]` in ServiceEventInfo being the
    uint8 array rosidl makes of it. Gives the rmw_zenoh design document's
    AddTwoInts hash (checked below)."""
    consts, fields = TS.fielddefs["service_msgs/msg/ServiceEventInfo"]
    fields = [(n, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16))) if n == "client_gid" else (n, d)
              for n, d in fields]
    TS.fielddefs["service_msgs/msg/ServiceEventInfo"] = (consts, fields)
    types = {}
    types.update(get_types_from_msg(request, f"{name}_Request"))
    types.update(get_types_from_msg(response, f"{name}_Response"))
    types.update(get_types_from_msg(
        f"service_msgs/msg/ServiceEventInfo info\n{name}_Request[<=1] request\n{name}_Response[<=1] response\n",
        f"{name}_Event"))
    types.update(get_types_from_msg(
        f"{name}_Request request_message\n{name}_Response response_message\n{name}_Event event_message\n", name))
    TS.register({_srv_path(k): _srv_path(v) for k, v in types.items()})
    return TS.hash_rihs01(name)


RESPONSE = "bool success\nstring message\n"
SET_BOOL = ("std_srvs/srv/SetBool", service_hash("std_srvs/srv/SetBool", "bool data\n", RESPONSE))
TRIGGER = ("std_srvs/srv/Trigger", service_hash("std_srvs/srv/Trigger", "", RESPONSE))


def test_the_service_hash_is_the_design_documents():
    assert service_hash("example_interfaces/srv/AddTwoInts", "int64 a\nint64 b\n", "int64 sum\n") == \
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def call_service(client, name, srv, request, sequence):
    """One request as rmw_zenoh's client sends it; (success, message, reply attachment)."""
    srv_type, srv_hash = srv
    attachment = struct.pack("<qqB", sequence, time.time_ns(), 16) + GID
    replies = list(client.get(f"0/{name.strip('/')}/{dds_name(srv_type)}/{srv_hash}",
                              payload=b"\x00\x01\x00\x00" + request, attachment=attachment, timeout=20.0))
    assert len(replies) == 1, replies
    reply = replies[0].ok
    assert reply is not None, replies[0].err
    body = bytes(reply.payload.to_bytes())
    assert body[:4] == b"\x00\x01\x00\x00"
    (length,) = struct.unpack_from("<I", body, 8)
    return body[4] == 1, body[12:12 + length - 1].decode(), bytes(reply.attachment.to_bytes())


def states(api):
    return [dev["state"] for dev in call(api, "GET", "/buses/sim0/devices")["devices"]]


def test_enable_and_estop_services(ros2):
    d, client = ros2
    api = d.url + "/api/v1"
    expected = {("%sim0%enable", dds_name(SET_BOOL[0]), SET_BOOL[1]),
                ("%sim0%estop", dds_name(TRIGGER[0]), TRIGGER[1])}

    def servers():
        tokens = [str(r.ok.key_expr).split("/") for r in client.liveliness().get("@ros2_lv/**")]
        return {(p[9], p[10], p[11]) for p in tokens if p[5] == "SS"}

    # The bridge declares its services once it is connected: on a loaded
    # host, after the daemon answers its API.
    wait_for("the bridge's services declared", lambda: servers() == expected or None)
    assert servers() == expected
    assert states(api) != ["run"] * 4

    ok, message, attachment = call_service(client, "/sim0/enable", SET_BOOL, b"\x01", 7)
    assert ok and "enabled every joint of bus `sim0`" in message, message
    seq, stamp, gid_len = struct.unpack_from("<qqB", attachment)
    assert (seq, gid_len, attachment[17:]) == (7, 16, GID), attachment
    assert abs(stamp / 1e9 - time.time()) < 5
    wait_for("every joint running", lambda: states(api) == ["run"] * 4)

    ok, message, _ = call_service(client, "/sim0/enable", SET_BOOL, b"\x00", 8)
    assert ok and "disabled" in message, message
    wait_for("every joint disabled", lambda: all(s != "run" for s in states(api)))

    call_service(client, "/sim0/enable", SET_BOOL, b"\x01", 9)
    wait_for("running again", lambda: states(api) == ["run"] * 4)
    ok, message, attachment = call_service(client, "/sim0/estop", TRIGGER, b"\x00", 10)
    assert ok and "e-stop: bus `sim0` stopped (4 confirmed" in message, message
    assert struct.unpack_from("<q", attachment)[0] == 10
    assert all(s != "run" for s in states(api)), states(api)



def refusal(api, path, body):
    """The problem document of a REST call that must be refused."""
    try:
        call(api, "POST", path, body)
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())
    raise AssertionError(f"POST {path} {body} was not refused")


def test_an_enable_over_ros2_is_the_cores_enable(tmp_path):
    """ROS 2's enable service, REST's and the WebSocket's (tests/ws_sim.rs)
    reach one core call: a hand naming a joint that is not on the bus is
    refused by the core's device check, in the same words on each, and
    nothing is enabled."""
    config = tmp_path / "jointd.toml"

    def args(endpoint):
        config.write_text(f"""
[[hand]]
name = "left"
joints = [{{ bus = "sim0", ids = "3-5", names = ["ring", "little", "extra"] }}]

[ros2]
enabled = true
namespace_by = "hand"
connect = ["{endpoint}"]
""")
        return ["--sim", "4", "--config", str(config)]

    with on_router(4, args) as (d, client):
        api = d.url + "/api/v1"
        code, problem = refusal(api, "/buses/sim0/control/enable", {"ids": [3, 4, 5]})
        assert 400 <= code < 500 and "5" in problem["detail"], problem
        ok, message, _ = call_service(client, "/left/enable", SET_BOOL, b"\x01", 1)
        assert not ok, message
        assert message == f"not enabled: joints [3, 4, 5] of bus `sim0`: {problem['detail']}", message
        assert all(s != "run" for s in states(api)), states(api)


def trajectory(names, points):
    T = TS.types
    Duration, Point = T["builtin_interfaces/msg/Duration"], T["trajectory_msgs/msg/JointTrajectoryPoint"]
    empty = np.array([], dtype=np.float64)
    m = T[TRAJECTORY](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""),
        joint_names=names,
        points=[Point(positions=np.array(p, dtype=np.float64), velocities=empty, accelerations=empty,
                      effort=empty, time_from_start=Duration(sec=int(t), nanosec=int(round(t % 1 * 1e9))))
                for t, p in points])
    return bytes(TS.serialize_cdr(m, TRAJECTORY))


def test_a_joint_trajectory_runs_as_a_move(ros2):
    d, client = ros2
    api = d.url + "/api/v1"
    call(api, "POST", "/buses/sim0/control/enable", {"ids": [1, 2]})
    wait_for("joints 1 and 2 running", lambda: states(api)[:2] == ["run", "run"])
    publisher = client.declare_publisher(key("/sim0/joint_trajectory", TRAJECTORY))
    # 0.3 rad = 17.19 deg, -0.2 rad = -11.46 deg; then 0.5 rad = 28.65 deg, -0.4 rad = -22.92 deg.
    publisher.put(trajectory(["sim0_1", "sim0_2"], [(0.0, [0.0, 0.0]), (0.4, [0.3, -0.2]), (1.0, [0.5, -0.4])]))
    first = wait_for("the move started", lambda: _move(api, 1))
    assert first["joints"] == [{"bus": "sim0", "id": 1}, {"bus": "sim0", "id": 2}], first
    assert first["duration_ms"] == 1000.0 and first["method"] == "min_jerk", first
    done = wait_for("the move done", lambda: (lambda m: m if m["state"] == "done" else None)(_move(api, 1)))
    assert len(done["arrived"]) == 2, done
    angle = lambda i: call(api, "GET", f"/buses/sim0/devices/{i}")["motion"]["angle_deg"]
    wait_for("joint 1 at 28.65 deg and joint 2 at -22.92 deg",
             lambda: abs(angle(1) - 28.648) < 0.5 and abs(angle(2) + 22.918) < 0.5)
    assert call(api, "GET", "/ros2")["commands_applied"] >= 1

    # A point outside the joint's range (10 rad = 573 deg): refused whole, no move.
    publisher.put(trajectory(["sim0_1"], [(0.5, [10.0])]))
    wait_for("the bad trajectory counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= 1)
    assert _move(api, 2) is None
    assert abs(angle(1) - 28.648) < 0.5


def _move(api, move_id):
    try:
        return call(api, "GET", f"/moves/{move_id}")
    except Exception as e:  # 404 until it exists
        if getattr(e, "code", None) == 404:
            return None
        raise


def test_dropped_commands_are_said_on_rosout_once_per_cause(ros2):
    d, client = ros2
    api = d.url + "/api/v1"
    logs = []
    client.declare_subscriber(key("/rosout", LOG), lambda s: logs.append(TS.deserialize_cdr(
        bytes(s.payload.to_bytes()), LOG)))
    publisher = client.declare_publisher(key("/sim0/joint_commands", "sensor_msgs/msg/JointState"))
    T = TS.types

    def command(names, rad):
        empty = np.array([], dtype=np.float64)
        m = T["sensor_msgs/msg/JointState"](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""),
            name=names, position=np.array(rad, dtype=np.float64), velocity=empty, effort=empty)
        return bytes(TS.serialize_cdr(m, "sensor_msgs/msg/JointState"))

    publisher.put(command(["pinky"], [0.1]))
    wait_for("one Log", lambda: logs)
    log = logs[0]
    assert (log.level, log.name) == (30, "jointd"), log
    assert "/sim0/joint_commands" in log.msg and "no joint named `pinky`" in log.msg, log.msg
    # The same cause again at once: counted, not said. Then another cause:
    # said; /rosout is published in order, so once it is here the second
    # unknown joint would have been too.
    publisher.put(command(["thumb"], [0.1]))
    wait_for("the second drop counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= 2)
    publisher.put(command(["sim0_1", "sim0_2"], [0.1]))
    wait_for("the malformed command said", lambda: len(logs) >= 2)
    assert "2 names but 1 positions" in logs[1].msg, logs[1].msg
    assert len(logs) == 2 and "thumb" not in logs[1].msg, [entry.msg for entry in logs]
    assert call(api, "GET", "/ros2")["commands_dropped"] == 3


def test_diagnostics_have_a_status_per_bus(ros2):
    d, client = ros2
    arrays = []
    client.declare_subscriber(key("/diagnostics", DIAGNOSTICS),
                              lambda s: arrays.append(TS.deserialize_cdr(bytes(s.payload.to_bytes()), DIAGNOSTICS)))
    # The first arrays may come before the bus's first statistics window.
    busy = lambda: arrays and any(kv.key == "occupancy_pct" and float(kv.value) > 0
                                  for kv in arrays[-1].status[0].values)
    wait_for("a diagnostic array with the line's occupancy", busy)
    names = [s.name for s in arrays[-1].status]
    assert names == ["jointd: bus sim0"] + [f"jointd: sim0_{i}" for i in range(1, 5)], names
    bus = arrays[-1].status[0]
    values = {kv.key: kv.value for kv in bus.values}
    assert (bus.level, bus.message, values["link"]) == (0, "link up", "up"), (bus, values)
    assert values["devices_online"] == "4/4", values
    assert 0.0 < float(values["occupancy_pct"]) <= 100.0, values
    assert int(values["timeouts"]) >= 0 and int(values["crc_errors"]) >= 0, values
    assert values["port"] == bus.hardware_id, values
