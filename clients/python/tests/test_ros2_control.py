"""The ROS 2 bridge as `robot_state_publisher` and `topic_based_ros2_control`
meet it: `[ros2.namespaces] sim0 = ""` gives plain `/joint_states` and
`/joint_commands`, and a `joint_commands` stream of velocities only (rad/s
at the output shaft, no positions) moves each joint that way at that speed;
when the stream stops, the watchdog stops the joints (no `[watchdog]` in
the config: velocity streams are always watched). Needs a jointd built with
`--features ros2` (CI's is)."""

import threading

import numpy as np
import zenoh

from conftest import Daemon
from test_ros2 import JOINT_STATE, TS, call, free_port, key, wait_for, zenoh_config


def velocities(names, rad_s):
    Cmd, Header, Time = (TS.types[t] for t in (JOINT_STATE, "std_msgs/msg/Header",
                                                "builtin_interfaces/msg/Time"))
    m = Cmd(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), name=names,
            position=np.array([], dtype=np.float64), velocity=np.array(rad_s, dtype=np.float64),
            effort=np.array([], dtype=np.float64))
    return bytes(TS.serialize_cdr(m, JOINT_STATE))


class Stream:
    """Publishes one command at 50 Hz until stopped, as a ros2_control loop."""

    def __init__(self, publisher, payload):
        self.stop_flag = threading.Event()
        self.thread = threading.Thread(target=self.run, args=(publisher, payload), daemon=True)
        self.thread.start()

    def run(self, publisher, payload):
        while not self.stop_flag.wait(0.02):
            publisher.put(payload)

    def stop(self):
        self.stop_flag.set()
        self.thread.join(5)


def test_plain_topics_and_velocity_commands(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(zenoh_config("router", "listen/endpoints", endpoint))
    config = tmp_path / "jointd.toml"
    config.write_text(f"""
[ros2]
enabled = true
connect = ["{endpoint}"]

[ros2.namespaces]
sim0 = ""
""")
    d = Daemon("--sim", "4", "--config", str(config))
    client = zenoh.open(zenoh_config("client", "connect/endpoints", endpoint))
    stream = None
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":4' in b, "4 joints online")
        api = d.url + "/api/v1"
        states = []
        client.declare_subscriber(key("/joint_states", JOINT_STATE),
                                  lambda s: states.append(bytes(s.payload.to_bytes())))
        wait_for("joint states on /joint_states", lambda: len(states) > 10)
        assert list(TS.deserialize_cdr(states[-1], JOINT_STATE).name) == [f"sim0_{i}" for i in range(1, 5)]
        tokens = [str(r.ok.key_expr) for r in client.liveliness().get("@ros2_lv/**")]
        assert any("/MP/%/%/jointd/%joint_states/" in t for t in tokens), tokens
        assert any("/MS/%/%/jointd/%joint_commands/" in t for t in tokens), tokens

        call(api, "POST", "/buses/sim0/control/enable", {"ids": [2, 3]})
        wait_for("joints running", lambda: all(
            call(api, "GET", f"/buses/sim0/devices/{i}")["status"]["state"] == "run" for i in (2, 3)))
        angle = lambda i: call(api, "GET", f"/buses/sim0/devices/{i}")["motion"]["angle_deg"]
        start2, start3 = angle(2), angle(3)

        # 0.3 rad/s = 17.2 deg/s up for joint 2, down for joint 3.
        publisher = client.declare_publisher(key("/joint_commands", JOINT_STATE))
        stream = Stream(publisher, velocities(["sim0_2", "sim0_3"], [0.3, -0.3]))
        wait_for("joint 2 up and joint 3 down by 10 deg",
                 lambda: angle(2) > start2 + 10 and angle(3) < start3 - 10)
        dev2 = call(api, "GET", "/buses/sim0/devices/2")
        # Toward the soft limit (the device's +255 deg here), 17.2 deg/s as the speed limit.
        assert dev2["target"]["position_deg"] > 250, dev2
        speed_dps = abs(dev2["motion"]["speed_dps"])
        assert 10 < speed_dps < 20, dev2
        status = call(api, "GET", "/ros2")
        assert status["commands_applied"] > 0 and status["commands_dropped"] == 0, status
        fired = status["watchdog_fired"]

        # The stream stops: the watchdog holds the joints where they are.
        stream.stop()
        stream = None
        wait_for("the watchdog fired", lambda: call(api, "GET", "/ros2")["watchdog_fired"] > fired)
        wait_for("joint 2 still", lambda: abs(call(api, "GET", "/buses/sim0/devices/2")["motion"]["speed_dps"]) < 0.5)
        held = [angle(2) for _ in range(10)]
        assert max(held) - min(held) < 1.0, held
        target = call(api, "GET", "/buses/sim0/devices/2")["target"]["position_deg"]
        assert abs(target - held[0]) < 2.0, (target, held)

        # Positions and velocities both missing: refused whole, counted.
        publisher.put(velocities(["sim0_2"], []))
        wait_for("the empty command counted", lambda: call(api, "GET", "/ros2")["commands_dropped"] >= 1)
        assert "neither positions nor velocities" in call(api, "GET", "/ros2")["last_dropped"]
    finally:
        if stream is not None:
            stream.stop()
        client.close()
        d.stop()
        router.close()
