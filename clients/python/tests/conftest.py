"""A real daemon on the simulator for every test: `target/debug/jointd`
(or $JOINTD_BIN), on a free port, killed at the end. Each daemon has a
TMPDIR of its own (the simulator's pty link, default recordings), removed
when it stops."""

import os
import pathlib
import shutil
import subprocess
import tempfile
import time
import urllib.request

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("JOINTD_BIN", str(ROOT / "target" / "debug" / "jointd"))


class Daemon:
    def __init__(self, *args):
        self.log = tempfile.NamedTemporaryFile("w+", prefix="jointd-", suffix=".log")
        self.tmp = tempfile.mkdtemp(prefix="jointd-test-")
        self.proc = subprocess.Popen([BIN, *args, "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE,
                                     stderr=self.log, text=True,
                                     env={**os.environ, "NO_COLOR": "1", "TMPDIR": self.tmp})
        first = self.proc.stdout.readline()
        assert first.startswith("listening on "), f"no address line: {first!r}"
        self.url = first.split()[-1]

    def wait(self, path, ok, what, timeout=20.0):
        deadline = time.monotonic() + timeout
        last = b"(no answer)"
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(self.url + path, timeout=2) as r:
                    last = r.read()
                    if ok(last):
                        return
            except OSError as e:
                last = str(e).encode()
            time.sleep(0.05)
        raise AssertionError(f"timed out waiting for {what}; {path} last said: {last[:600]!r}")

    def log_text(self):
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.log.close()
        shutil.rmtree(self.tmp, ignore_errors=True)


@pytest.fixture()
def daemon():
    """`jointd --sim 4`, every joint online."""
    d = Daemon("--sim", "4")
    d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":4' in b, "4 joints online")
    yield d
    d.stop()


@pytest.fixture()
def down_daemon():
    """A daemon whose only bus names a serial device that does not exist."""
    d = Daemon("--bus", f"gone=/tmp/jointd-no-such-tty-{os.getpid()}@500000")
    d.wait("/api/v1/buses/gone", lambda b: b'"link":"down"' in b, "the bus down")
    yield d
    d.stop()
