"""Recordings read back by the MCAP reference reader: `jointd
record` against a daemon on the simulator while a joint moves; Python's
`mcap` and `mcap-ros2-support` decode the joint states against the real
`sensor_msgs/msg/JointState` definition; their count matches the telemetry
rate the REST API reports (within 5 %), their positions what it reported,
and the raw frames decode with `jointd frame decode --mcap`."""

import json
import math
import subprocess
import threading
import time
import urllib.request

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import BIN

SECONDS = 5.0


def call(base, method, path, body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read() or b"null")


def recording_daemon(tmp_path, joints):
    """A daemon of its own on `joints` simulated joints, its state in
    `tmp_path`, recording once they are online: (daemon, the recording)."""
    from conftest import Daemon

    d = Daemon("--sim", str(joints), "--state-dir", str(tmp_path))
    try:
        d.wait("/api/v1/buses/sim0", lambda b: f'"devices_online":{joints}'.encode() in b,
               f"{joints} joints online")
        return d, call(d.url + "/api/v1", "POST", "/recordings", {})
    except BaseException:
        d.stop()
        raise


def test_a_recording_of_a_moving_joint_reads_back(daemon, tmp_path):
    api = daemon.url + "/api/v1"
    call(api, "POST", "/buses/sim0/control/enable", {"ids": [1, 2, 3, 4]})
    # The first enable aligns for about a second; targets wait for `run`.
    daemon.wait("/api/v1/buses/sim0/devices",
                lambda b: all(d["state"] == "run" for d in json.loads(b)["devices"]),
                "the joints to finish aligning")
    out = tmp_path / "run.mcap"
    rec = subprocess.Popen([BIN, "record", "--out", str(out), "--duration", str(SECONDS),
                            "--url", daemon.url], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    # While it records: the telemetry rate the API reports (each a 1 s
    # window, read every 250 ms from the second second on), and a move of joint 1.
    rates = []

    def read_rates():
        time.sleep(1.0)
        while rec.poll() is None and len(rates) < 4 * (SECONDS - 1.5):
            devices = call(api, "GET", "/buses/sim0/devices")["devices"]
            rates.append(sum(d["telemetry_hz"] for d in devices) / len(devices))
            time.sleep(0.25)

    reading = threading.Thread(target=read_rates)
    reading.start()
    time.sleep(1.5)
    call(api, "PATCH", "/buses/sim0/devices/3/config", {"pos_kp": 1.25})
    move = call(api, "POST", "/moves", {"joints": [{"bus": "sim0", "id": 1, "position_deg": 30}],
                                         "duration_ms": 1500, "method": "min_jerk"})
    stdout, stderr = rec.communicate(timeout=SECONDS + 30)
    reading.join()
    assert rec.returncode == 0, stderr
    status = json.loads(stdout)
    assert status["state"] == "finished", status
    final = call(api, "GET", "/buses/sim0/devices/1")

    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        topics = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].name)
                  for c in summary.channels.values()}
        assert topics["/sim0/joint_states"] == ("cdr", "sensor_msgs/msg/JointState")
        assert topics["/jointd/sim0/frames"] == ("json", "jointd/Frame")
        # JSON channels: the file is no ros2-profile file; the CDR channel
        # still carries the QoS a ROS 2 publisher of it offers.
        assert reader.get_header().profile == ""
        for c in summary.channels.values():
            assert ("offered_qos_profiles" in c.metadata) == (c.message_encoding == "cdr"), c
        states = [(m.log_time, d) for _, _, m, d in
                  reader.iter_decoded_messages(topics=["/sim0/joint_states"])]

    assert len(states) == status["messages"]["/sim0/joint_states"]
    span_s = (states[-1][0] - states[0][0]) / 1e9
    rate = (len(states) - 1) / span_s
    expected = sum(rates) / len(rates)
    # A sample lost or written twice in every few shows as a rate far off;
    # the API's rate is read in 1 s windows that the config write and the
    # move make uneven, by up to 6 % on a loaded host.
    assert abs(rate - expected) / expected < 0.10, f"{rate:.1f} msgs/s against {expected:.1f} Hz"
    for _, d in states:
        assert d.name == ["sim0_1", "sim0_2", "sim0_3", "sim0_4"], d.name
        assert len(d.position) == len(d.velocity) == len(d.effort) == 4
    # Joint 1 moved from 0 to 30 degrees: the recording saw it go, and its
    # last angle is what the API reported at the end (rad in ROS).
    angles = [math.degrees(d.position[0]) for _, d in states]
    assert min(angles) < 1.0 and max(angles) > 29.0, (min(angles), max(angles))
    assert abs(angles[-1] - final["motion"]["angle_deg"]) < 0.2, (angles[-1], final["motion"])
    assert max(d.velocity[0] for _, d in states) > math.radians(10), "it was seen moving"

    # Device events: the config write made while recording is one.
    with open(out, "rb") as f:
        events = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/jointd/sim0/events"])]
    written = [e for e in events if e["event"] == "config_written"]
    assert any(e["id"] == 3 and e["name"] == "SET_POS_KP" for e in written), events
    assert any(e["event"] == "move_started" for e in events), events

    # The move's targets, as the daemon sent them each control cycle: on the
    # setpoints channel with their source, in time order, ending at its goal.
    with open(out, "rb") as f:
        setpoints = [(m.log_time, json.loads(m.data)) for _, _, m in
                     make_reader(f).iter_messages(topics=["/jointd/sim0/setpoints"])]
    of_move = [(t, s) for t, s in setpoints
               if s["source"] == "move" and s["move_id"] == move["id"]]
    assert len(of_move) > 100, f"{len(of_move)} targets of a 1.5 s move"
    times = [t for t, _ in of_move]
    seqs = [s["seq"] for _, s in of_move]
    assert times == sorted(times) and seqs == sorted(seqs), "time-ordered"
    path = [s["targets"][0]["position_deg"] for _, s in of_move]
    assert all(s["targets"][0]["id"] == 1 for _, s in of_move)
    assert path[0] < 1.0 and path == sorted(path), path[:5]
    assert path[-1] == 30.0, f"the last target {path[-1]} is the goal"

    frames = subprocess.run([BIN, "frame", "decode", "--mcap", str(out)], capture_output=True,
                            text=True, timeout=60, check=True).stdout.splitlines()
    assert len(frames) == status["messages"]["/jointd/sim0/frames"]
    kinds = {json.loads(line)["decoded"]["kind"] for line in frames}
    assert {"reply", "config"} <= kinds, kinds
    broadcast = [json.loads(line) for line in frames if json.loads(line)["direction"] == "tx"]
    assert broadcast, "host frames are there too"


def test_an_api_recording_is_listed_stopped_and_downloaded(daemon):
    api = daemon.url + "/api/v1"
    started = call(api, "POST", "/recordings", {})
    assert started["state"] == "recording"
    assert any(r["id"] == started["id"] for r in call(api, "GET", "/recordings")["recordings"])
    try:
        call(api, "GET", f"/recordings/{started['id']}/file")
        raise AssertionError("a running recording has no file yet")
    except urllib.error.HTTPError as e:
        assert e.code == 409
    time.sleep(0.5)
    stopped = call(api, "DELETE", f"/recordings/{started['id']}")
    assert stopped["state"] == "finished"
    assert stopped["messages"]["/sim0/joint_states"] > 0
    with urllib.request.urlopen(f"{api}/recordings/{started['id']}/file", timeout=10) as r:
        body = r.read()
    assert body[:8] == b"\x89MCAP0\r\n" and body[-8:] == b"\x89MCAP0\r\n"


def test_a_kill_loses_at_most_the_last_chunk(tmp_path):
    from mcap.stream_reader import StreamReader
    from mcap.records import Message

    d, started = recording_daemon(tmp_path, 4)
    try:
        time.sleep(3.5)
        d.proc.kill()  # SIGKILL: no footer, no summary, the open chunk lost
        d.proc.wait(10)
    finally:
        d.stop()
    path = tmp_path / "recordings" / started["file"]
    stamps = []
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Message):
                    stamps.append(record.log_time)
    except Exception:  # the cut end: everything before it was read
        pass
    # Chunks close every second: at least 2 of the 3.5 s are whole.
    assert stamps, "nothing survived"
    assert (max(stamps) - min(stamps)) / 1e9 >= 2.0, (max(stamps) - min(stamps)) / 1e9
    frames = subprocess.run([BIN, "frame", "decode", "--mcap", str(path)], capture_output=True,
                            text=True, timeout=60)
    assert frames.returncode == 0, frames.stderr
    assert len(frames.stdout.splitlines()) > 1000


def test_a_bag_compatible_recording_has_one_ros_serialization(daemon, tmp_path):
    out = tmp_path / "bag.mcap"
    rec = subprocess.run([BIN, "record", "--out", str(out), "--duration", "1.5", "--bag-compatible",
                          "--url", daemon.url], capture_output=True, text=True, timeout=60)
    assert rec.returncode == 0, rec.stderr
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        channels = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].encoding,
                              summary.schemas[c.schema_id].name) for c in summary.channels.values()}
        assert all(enc == "cdr" and schema == "ros2msg" for enc, schema, _ in channels.values()), channels
        # The ros2 profile's requirements: CDR, ros2msg, and each channel's
        # offered QoS as rosbag2 writes it (a YAML list of profiles).
        assert reader.get_header().profile == "ros2"
        for c in summary.channels.values():
            qos = c.metadata.get("offered_qos_profiles", "")
            assert qos.startswith("- history: keep_last\n"), (c.topic, qos)
            for line in ("depth: 10", "reliability: reliable", "durability: volatile",
                         "liveliness: automatic", "avoid_ros_namespace_conventions: false"):
                assert f"\n  {line}\n" in qos, (c.topic, line, qos)
        assert channels["/jointd/sim0/frames"][2] == "std_msgs/msg/String"
        frames = [json.loads(d.data) for _, _, _, d in
                  reader.iter_decoded_messages(topics=["/jointd/sim0/frames"])]
    assert frames and {"dir", "wire_time_ns", "hex"} <= frames[0].keys()
    decoded = subprocess.run([BIN, "frame", "decode", "--mcap", str(out)], capture_output=True,
                             text=True, timeout=60, check=True).stdout.splitlines()
    assert len(decoded) == len(frames)


def test_a_recording_running_at_shutdown_is_closed_whole(tmp_path):
    d, started = recording_daemon(tmp_path, 2)
    try:
        time.sleep(1.0)
    finally:
        d.stop()  # SIGTERM: a graceful stop
    path = tmp_path / "recordings" / started["file"]
    body = path.read_bytes()
    # A finished file ends with the footer and the closing magic; a cut one
    # ends with its last whole chunk.
    assert body[-8:] == b"\x89MCAP0\r\n", "the file was not closed"
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None and summary.statistics.message_count > 0


def test_the_metadata_record_names_every_joint_with_its_firmware_and_calibration(tmp_path):
    """The `jointd` Metadata record: the daemon's version, and each joint's
    bus, id, name, hand, firmware and calibration as the API reports them."""
    from conftest import Daemon

    config = tmp_path / "jointd.toml"
    config.write_text("""
[[hand]]
name = "left"
joints = [{ bus = "sim0", ids = "2-3", names = ["index", "middle"] }]
""")
    d = Daemon("--sim", "4", "--config", str(config), "--state-dir", str(tmp_path))
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":4' in b, "4 joints online")
        api = d.url + "/api/v1"
        call(api, "PUT", "/buses/sim0/devices/3/calibration",
             {"offset_deg": -10.0, "flip": True, "range_deg": [-20.0, 60.0]})
        # Each joint's protocol revision is learnt after it comes online (a
        # busy host may take a while): read the devices once all are known,
        # so the recording and this read see the same.
        deadline = time.monotonic() + 20
        while True:
            devices = {dev["id"]: call(api, "GET", f"/buses/sim0/devices/{dev['id']}")
                       for dev in call(api, "GET", "/buses/sim0/devices")["devices"]}
            if all(v["protocol"] and v["protocol"].get("revision") for v in devices.values()):
                break
            assert time.monotonic() < deadline, f"protocol revisions never all known: {devices}"
            time.sleep(0.05)
        version = call(d.url, "GET", "/healthz")["version"]
        started = call(api, "POST", "/recordings", {"duration_s": 0.5})
        d.wait(f"/api/v1/recordings/{started['id']}", lambda b: b'"finished"' in b, "finished")
        with urllib.request.urlopen(f"{api}/recordings/{started['id']}/file", timeout=10) as r:
            body = r.read()
    finally:
        d.stop()
    out = tmp_path / "meta.mcap"
    out.write_bytes(body)
    with open(out, "rb") as f:
        records = [m for m in make_reader(f).iter_metadata() if m.name == "jointd"]
    assert len(records) == 1, records
    meta = records[0].metadata
    assert meta["jointd_version"] == version, meta
    joints = json.loads(meta["joints"])
    assert [(j["bus"], j["id"]) for j in joints] == [("sim0", i) for i in (1, 2, 3, 4)], joints
    by_id = {j["id"]: j for j in joints}
    assert [by_id[i]["name"] for i in (1, 2, 3, 4)] == ["sim0_1", "index", "middle", "sim0_4"]
    assert [by_id[i]["hand"] for i in (1, 2, 3, 4)] == [None, "left", "left", None]
    for i, j in by_id.items():
        assert j["online"] is True
        assert j["firmware"] == devices[i]["firmware"] and j["firmware"], (j, devices[i])
        assert j["protocol_revision"] == (devices[i]["protocol"] or {}).get("revision"), j
    assert by_id[3]["calibration"] == {"offset_deg": -10.0, "flip": True, "range_deg": [-20.0, 60.0]}
    assert by_id[1]["calibration"] == {"offset_deg": 0.0, "flip": False, "range_deg": None}


def test_every_json_message_validates_against_its_channels_schema(daemon):
    """A recording through enables, a config write, a REST target, a move
    and an e-stop: every message of each JSON channel validates against the
    JSON schema the file gives that channel (closed schemas: a field a
    message carries and its schema does not list fails)."""
    import jsonschema

    api = daemon.url + "/api/v1"
    started = call(api, "POST", "/recordings", {})
    call(api, "POST", "/buses/sim0/control/enable", {"ids": [1, 2, 3, 4]})
    for i in (1, 2):
        daemon.wait(f"/api/v1/buses/sim0/devices/{i}", lambda b: b'"state":"run"' in b,
                    f"joint {i} running")
    call(api, "PATCH", "/buses/sim0/devices/3/config", {"pos_kp": 1.25})
    call(api, "PUT", "/buses/sim0/control/targets", {"targets": [{"id": 2, "position_deg": -5.0}]})
    move = call(api, "POST", "/moves", {"joints": [{"bus": "sim0", "id": 1, "position_deg": 10}],
                                         "duration_ms": 300, "method": "linear"})
    daemon.wait(f"/api/v1/moves/{move['id']}", lambda b: b'"state":"done"' in b, "the move done")
    call(api, "POST", "/estop", {})
    stopped = call(api, "DELETE", f"/recordings/{started['id']}")
    assert stopped["state"] == "finished", stopped
    with urllib.request.urlopen(f"{api}/recordings/{started['id']}/file", timeout=10) as r:
        body = r.read()

    import io
    reader = make_reader(io.BytesIO(body))
    summary = reader.get_summary()
    validators = {}
    for c in summary.channels.values():
        schema = summary.schemas[c.schema_id]
        if c.message_encoding == "json":
            assert schema.encoding == "jsonschema", (c.topic, schema.encoding)
            doc = json.loads(schema.data)
            jsonschema.validators.validator_for(doc).check_schema(doc)
            validators[c.id] = jsonschema.validators.validator_for(doc)(doc)
    assert len(validators) == 3, "frames, events, setpoints"
    seen = {}
    for _, channel, message in reader.iter_messages():
        if channel.id in validators:
            msg = json.loads(message.data)
            errors = [e.message for e in validators[channel.id].iter_errors(msg)]
            assert not errors, (channel.topic, msg, errors)
            seen.setdefault(channel.topic, set()).add(msg.get("event") or msg.get("source") or "frame")
    assert {"config_written", "move_started", "move_done", "estop"} <= seen["/jointd/sim0/events"], seen
    assert {"rest", "move"} <= seen["/jointd/sim0/setpoints"], seen
    assert seen["/jointd/sim0/frames"] == {"frame"}
