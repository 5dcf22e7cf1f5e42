"""Grasping over ROS 2, as a ROS 2 node on rmw_zenoh with only standard
message packages meets it: with `namespace_by = "hand"`, a
`control_msgs/msg/GripperCommand` on `/right/gripper_command` (its type
hash computed here from the definition, by the method that gives the
published JointState and AddTwoInts hashes) grasps the hand; the finger
with a simulator object holds it with contact, the others end without;
`/right/grasp_state` (`diagnostic_msgs/msg/DiagnosticArray`) and REST's
`GET /api/v1/grasps/{id}` say so. `grasp_release` (std_srvs/srv/Trigger)
opens the hand, the e-stop service ends a grasp, and bad commands are
refused, said on `/rosout` and counted in `GET /api/v1/ros2`. Needs a
jointd built with `--features ros2`."""

import math
import struct

import pytest
from rosbags.typesys import get_types_from_msg

from conftest import Daemon
from test_ros2 import DIAGNOSTICS, TS, call, dds_name, key, on_router, wait_for
from test_ros2_services import LOG, SET_BOOL, TRIGGER, call_service

GRIPPER = "control_msgs/msg/GripperCommand"
# control_msgs' definition (Jazzy): two float64, no constants.
TS.register(get_types_from_msg("float64 position\nfloat64 max_effort\n", GRIPPER))
HOLD_A = 0.2
SPEED_DPS = 45.0


def test_the_hash_method_gives_the_published_hashes():
    # `ros2 interface` / `ros2 topic info --verbose` on Jazzy print these.
    assert TS.hash_rihs01("sensor_msgs/msg/JointState") == \
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
    assert TS.hash_rihs01(GRIPPER) == \
        "RIHS01_57eb8f326c9889ca8bb34ead82cc94cc09bf6bc5c3b6c09546dca3a00b589890"


def gripper(position, max_effort):
    m = TS.types[GRIPPER](position=position, max_effort=max_effort)
    return bytes(TS.serialize_cdr(m, GRIPPER))


@pytest.fixture()
def hand(tmp_path):
    """`jointd --sim 3`, an object before joint 1 at 15 deg, hand `right`
    of joints 1-3 (thumb, index, middle) with its own namespace."""
    config = tmp_path / "jointd.toml"

    def daemon_args(endpoint):
        config.write_text(f"""
[[hand]]
name = "right"
joints = [{{ bus = "sim0", ids = "1-3", names = ["thumb", "index", "middle"] }}]

[ros2]
enabled = true
namespace_by = "hand"
grasp_speed_dps = {SPEED_DPS}
connect = ["{endpoint}"]
""")
        return ["--sim", "3", "--sim-object", "1=15:0.05", "--config", str(config)]

    with on_router(3, daemon_args) as pair:
        yield pair


class Follow:
    """Every message of a topic, decoded."""

    def __init__(self, client, topic, ros_type):
        self.msgs = []
        self.sub = client.declare_subscriber(key(topic, ros_type), lambda s: self.msgs.append(
            TS.deserialize_cdr(bytes(s.payload.to_bytes()), ros_type)))


def fingers(array):
    """{joint: {"level", "message", **values}} of a grasp_state message, and the job's status."""
    job, *rest = array.status
    out = {}
    for s in rest:
        joint = s.name.rsplit(" ", 1)[1]
        out[joint] = {"level": s.level, "message": s.message, "hardware_id": s.hardware_id,
                      **{kv.key: kv.value for kv in s.values}}
    return {kv.key: kv.value for kv in job.values}, out


def latest_state(states, ok):
    """The newest grasp_state for which ok(job, fingers) holds."""
    def look():
        for array in reversed(states.msgs):
            job, f = fingers(array)
            if ok(job, f):
                return job, f
        return None
    return look


def grasp(api, grasp_id):
    """The grasp, or None while there is none with that id (404)."""
    try:
        return call(api, "GET", f"/grasps/{grasp_id}")
    except Exception as e:
        if getattr(e, "code", None) == 404:
            return None
        raise


def by_joint(view):
    return {f["joint"]: f for f in view["fingers"]}


def enable(api, client):
    ok, message, _ = call_service(client, "/right/enable", SET_BOOL, b"\x01", 1)
    assert ok, message
    wait_for("every finger running", lambda: all(
        call(api, "GET", f"/buses/sim0/devices/{i}")["status"]["state"] == "run" for i in (1, 2, 3)))


def test_a_gripper_command_grasps_and_the_services_end_it(hand):
    d, client = hand
    api = d.url + "/api/v1"
    def endpoints():
        tokens = [str(r.ok.key_expr).split("/") for r in client.liveliness().get("@ros2_lv/**")]
        return {(p[5], p[9]): (p[10], p[11]) for p in tokens if len(p) > 11}

    # Declared once the bridge is connected: on a loaded host, after the API answers.
    endpoints = wait_for("the hand's grasp endpoints declared",
                         lambda: (lambda e: e if ("MP", "%right%grasp_state") in e else None)(endpoints()))
    assert endpoints[("MS", "%right%gripper_command")] == (dds_name(GRIPPER), TS.hash_rihs01(GRIPPER)), endpoints
    assert endpoints[("MP", "%right%grasp_state")] == (dds_name(DIAGNOSTICS), TS.hash_rihs01(DIAGNOSTICS))
    for service in ("grasp_release", "grasp_stop", "estop"):
        assert endpoints[("SS", f"%right%{service}")] == (dds_name(TRIGGER[0]), TRIGGER[1]), service

    enable(api, client)
    states = Follow(client, "/right/grasp_state", DIAGNOSTICS)
    command = client.declare_publisher(key("/right/gripper_command", GRIPPER))
    # 25 deg for every finger: the thumb meets its object at 15 deg, the others close in free air.
    command.put(gripper(math.radians(25.0), HOLD_A))

    job, f = wait_for("the thumb holding, the others without contact", latest_state(
        states, lambda job, f: f["thumb"]["message"] == "holding"
        and f["index"]["message"] == f["middle"]["message"] == "no_contact"))
    assert job["grasp_id"] == "1" and job["state"] == "running", job
    assert float(job["hold_current_a"]) == HOLD_A
    assert f["thumb"]["contact"] == "true" and f["thumb"]["hardware_id"] == "sim0/1", f["thumb"]
    assert 14.5 <= math.degrees(float(f["thumb"]["contact_rad"])) <= 16.5, f["thumb"]
    assert f["thumb"]["level"] == 0 and f["index"]["level"] == 1, f
    assert f["index"]["contact"] == "false" and f["index"]["contact_rad"] == "", f["index"]
    assert abs(float(f["index"]["close_to_rad"]) - math.radians(25.0)) < 1e-3, f["index"]
    near_hold = lambda q: q != "" and abs(float(q) - HOLD_A) <= 0.1 * HOLD_A  # noqa: E731
    wait_for("the thumb holding with the hold current", latest_state(
        states, lambda job, f: near_hold(f["thumb"]["q_current_a"])))

    view = grasp(api, 1)
    assert view["hand"] == "right" and view["state"] == "running", view
    assert view["settings"]["speed_dps"] == SPEED_DPS and view["settings"]["hold_current_a"] == HOLD_A, view
    g = by_joint(view)
    assert g["thumb"]["state"] == "holding" and g["thumb"]["contact"] is True, g["thumb"]
    assert g["index"]["state"] == g["middle"]["state"] == "no_contact", g
    assert call(api, "GET", "/ros2")["commands_applied"] == 1
    # A second command while the hand grasps: refused (one grasp per finger), the grasp goes on.
    command.put(gripper(math.radians(25.0), HOLD_A))
    wait_for("the second command refused", lambda: call(api, "GET", "/ros2")["commands_dropped"] == 1)
    assert "is in grasp 1" in call(api, "GET", "/ros2")["last_dropped"]
    assert grasp(api, 1)["state"] == "running" and grasp(api, 2) is None

    ok, message, attachment = call_service(client, "/right/grasp_release", TRIGGER, b"\x00", 2)
    assert ok and message.startswith("grasp 1 released: thumb released (limit restored)"), message
    assert struct.unpack_from("<q", attachment)[0] == 2
    view = grasp(api, 1)
    assert view["state"] == "done" and all(
        f["state"] == "released" and f["current_limit_restored"] for f in view["fingers"]), view
    wait_for("the release on grasp_state", latest_state(
        states, lambda job, f: job["state"] == "done" and all(x["message"] == "released" for x in f.values())))
    ok, message, _ = call_service(client, "/right/grasp_release", TRIGGER, b"\x00", 3)
    assert not ok and "no grasp running on hand `right`" in message, message

    # NaN: each finger to the hand's pose `closed`.
    call(api, "PUT", "/hands/right/poses/closed", {"positions_deg": {"thumb": 20.0, "index": 12.0, "middle": 14.0}})
    command.put(gripper(float("nan"), HOLD_A))
    wait_for("grasp 2 with the thumb holding", lambda: (lambda v: v and by_joint(v)["thumb"]["state"] == "holding")(
        grasp(api, 2)))
    g = by_joint(grasp(api, 2))
    assert [g[j]["close_to_deg"] for j in ("thumb", "index", "middle")] == [20.0, 12.0, 14.0], g

    # The e-stop service ends it.
    ok, message, _ = call_service(client, "/right/estop", TRIGGER, b"\x00", 4)
    assert ok, message
    view = wait_for("grasp 2 aborted", lambda: (lambda v: v if v["state"] == "done" else None)(grasp(api, 2)))
    assert all(f["state"] == "aborted" and f["reason"] for f in view["fingers"]), view
    job, f = wait_for("the abort on grasp_state", latest_state(
        states, lambda job, f: job["grasp_id"] == "2" and job["state"] == "done"))
    assert all(x["message"] == "aborted" and x["level"] == 2 for x in f.values()), f


def test_bad_gripper_commands_are_refused_said_and_counted(hand):
    d, client = hand
    api = d.url + "/api/v1"
    logs = Follow(client, "/rosout", LOG)
    command = client.declare_publisher(key("/right/gripper_command", GRIPPER))

    def refused(n, payload, *words):
        command.put(payload)
        wait_for(f"drop {n} counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= n)
        status = call(api, "GET", "/ros2")
        assert all(w in status["last_dropped"] for w in words), status
        wait_for(f"Log {n} on /rosout", lambda: len(logs.msgs) >= n)
        log = logs.msgs[n - 1]
        assert (log.level, log.name) == (30, "jointd"), log
        assert "a gripper command on /right/gripper_command dropped whole" in log.msg, log.msg
        assert all(w in log.msg for w in words), log.msg

    # Fingers not enabled yet: the control core refuses, in REST's words.
    refused(1, gripper(math.radians(25.0), HOLD_A), "enable")
    enable(api, client)
    refused(2, gripper(math.radians(25.0), float("nan")), "max_effort = NaN")
    refused(3, gripper(math.radians(25.0), -0.1), "hold_current_a")
    # Below where the fingers stand (0 deg): it would open them.
    refused(4, gripper(-0.2, HOLD_A), "would open", "joint `thumb`")
    refused(5, b"\x00\x01\x00\x00\x00", "not a control_msgs/msg/GripperCommand")
    assert call(api, "GET", "/ros2")["commands_applied"] == 0
    assert grasp(api, 1) is None, "no grasp started"


def test_a_grasp_started_over_rest_is_followed_and_stopped_over_ros2(hand):
    d, client = hand
    api = d.url + "/api/v1"
    enable(api, client)
    states = Follow(client, "/right/grasp_state", DIAGNOSTICS)
    ok, message, _ = call_service(client, "/right/grasp_stop", TRIGGER, b"\x00", 1)
    assert not ok and "no grasp running on hand `right`" in message, message
    call(api, "POST", "/hands/right/grasp", {"speed_dps": 30.0, "hold_current_a": HOLD_A,
                                             "joints": [{"joint": "thumb", "close_to_deg": 25.0}]})
    job, f = wait_for("the REST grasp on grasp_state, holding", latest_state(
        states, lambda job, f: f.get("thumb", {}).get("message") == "holding"))
    assert job["grasp_id"] == "1" and list(f) == ["thumb"], (job, f)
    ok, message, _ = call_service(client, "/right/grasp_stop", TRIGGER, b"\x00", 2)
    assert ok and message == "grasp 1 stopped: thumb stopped (limit restored)", message
    assert grasp(api, 1)["fingers"][0]["state"] == "stopped"
    wait_for("the stop on grasp_state", latest_state(
        states, lambda job, f: job["state"] == "done" and f["thumb"]["message"] == "stopped"))


def test_a_hand_has_its_grasp_topics_with_namespaces_by_bus(tmp_path):
    """With `namespace_by = "bus"` joint states, commands, enable and estop
    are per bus, and a named hand still gets its grasp under its name."""
    config = tmp_path / "jointd.toml"

    def daemon_args(endpoint):
        config.write_text(f"""
[[hand]]
name = "right"
joints = [{{ bus = "sim0", ids = "1-3", names = ["thumb", "index", "middle"] }}]

[ros2]
enabled = true
namespace_by = "bus"
connect = ["{endpoint}"]
""")
        return ["--sim", "3", "--config", str(config)]

    with on_router(3, daemon_args) as (d, client):
        tokens = [str(r.ok.key_expr).split("/") for r in client.liveliness().get("@ros2_lv/**")]
        endpoints = {(p[5], p[9]): (p[10], p[11]) for p in tokens if len(p) > 11}
        assert ("MP", "%sim0%joint_states") in endpoints, endpoints
        assert endpoints[("MS", "%right%gripper_command")] == (dds_name(GRIPPER), TS.hash_rihs01(GRIPPER)), endpoints
        assert endpoints[("MP", "%right%grasp_state")] == (dds_name(DIAGNOSTICS), TS.hash_rihs01(DIAGNOSTICS))
        for service in ("grasp_release", "grasp_stop"):
            assert endpoints[("SS", f"%right%{service}")] == (dds_name(TRIGGER[0]), TRIGGER[1]), service
