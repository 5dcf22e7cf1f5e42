"""examples/teleop.py on the package: streams, gets acks, ends cleanly."""

import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[3]


def test_teleop_streams_and_finishes_without_a_watchdog_firing(daemon):
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "teleop.py"), "--url", daemon.url,
                          "--enable", "--seconds", "1", "--rate-hz", "200"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 errors" in out.stdout, out.stdout
    log = daemon.log_text()
    assert "watchdog fired" not in log, log
