"""Records what a public host program sends, for tests/vectors/public_programs.json.

Runs the program's own `Motor` class unchanged, imported from a directory
outside this repository (its code is never copied in), against
`jointd sim --firmware 2.0.8` through a pty relay that logs every byte the
program writes, and notes after each call what the simulated devices did.

    git -C <ParaHandSDK checkout> show HEAD:motor.py > /tmp/parahand/motor.py
    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install pyserial
    /tmp/venv/bin/python tools/record_public_programs.py /tmp/parahand target/debug/jointd 230400 out.json
"""
import json, os, pty, select, subprocess, sys, threading, time, tty

SDK_DIR, JOINTD, BAUD = sys.argv[1], sys.argv[2], int(sys.argv[3])
sys.path.insert(0, SDK_DIR)

sim = subprocess.Popen([JOINTD, "sim", "--ids", "1-2", "--baud", str(BAUD), "--firmware", "2.0.8",
                        "--align-ms", "100"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
sim_path = sim.stdout.readline().strip()
sim_fd = os.open(sim_path, os.O_RDWR | os.O_NOCTTY)
tty.setraw(sim_fd)
master, slave = pty.openpty()
tty.setraw(master); tty.setraw(slave)
slave_name = os.ttyname(slave)
host_bytes = bytearray()
lock = threading.Lock()

def relay():
    while True:
        r, _, _ = select.select([master, sim_fd], [], [], 0.05)
        if master in r:
            b = os.read(master, 4096)
            with lock:
                host_bytes.extend(b)
            os.write(sim_fd, b)
        if sim_fd in r:
            os.write(master, os.read(sim_fd, 4096))

threading.Thread(target=relay, daemon=True).start()

def devices():
    """The simulator console's `devices` answer (one JSON line on stderr)."""
    sim.stdin.write("devices\n"); sim.stdin.flush()
    while True:
        line = sim.stderr.readline()
        if line.startswith("["):
            return [{k: d[k] for k in ("id", "firmware", "fsm", "enabled", "angle_deg", "target_deg", "mode")}
                    for d in json.loads(line)]

from motor import Motor  # the public program's own module, unchanged
m = Motor(port=slave_name, baudrate=BAUD)
assert m.connect()
calls = []

def call(label, fn, settle=0.4):
    with lock:
        start = len(host_bytes)
    fn()
    time.sleep(settle)
    with lock:
        sent = bytes(host_bytes[start:])
    frames = [sent[i:i + 20].hex(" ").upper() for i in range(0, len(sent), 20)]
    calls.append({"call": label, "frames": frames, "devices_after": devices()})

import math
call("enable_motor(1, True)", lambda: m.enable_motor(1, True), 0.5)
call("set_motor_angle(1, math.radians(30.0), speed=0.5)", lambda: m.set_motor_angle(1, math.radians(30.0), 0.5), 1.0)
call("enable_motor(1, False)", lambda: m.enable_motor(1, False))
call("enable_all_motors(True)", lambda: m.enable_all_motors(True), 0.5)
call("set_motor_angles_broadcast({1: 10.0, 2: -20.0})", lambda: m.set_motor_angles_broadcast({1: 10.0, 2: -20.0}), 1.0)
call("set_motor_speeds_broadcast({1: 10.0, 2: 10.0})", lambda: m.set_motor_speeds_broadcast({1: 10.0, 2: 10.0}))
call("set_motor_currents_broadcast({1: 100, 2: 100})", lambda: m.set_motor_currents_broadcast({1: 100, 2: 100}))
call("get_motor_status(2, sync=False)", lambda: m.get_motor_status(2))
call("jog_motor(1, 1)", lambda: m.jog_motor(1, 1), 0.6)
call("enable_all_motors(False)", lambda: m.enable_all_motors(False))
call("enable_motors_broadcast({1: True, 2: True})", lambda: m.enable_motors_broadcast({1: True, 2: True}), 0.5)
call("enable_all_motors_broadcast(False)", lambda: m.enable_all_motors_broadcast(False))
call("emergency_stop()", lambda: m.emergency_stop())
m.disconnect()
sim.terminate()
open(sys.argv[4], "w").write(json.dumps(calls, indent=1))
