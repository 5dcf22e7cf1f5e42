"""Every `curl` line of the README, in order, as printed, against the
daemon of the README's first command (`--sim 16`, here on a free port):
each must answer 2xx, except the line the README shows failing, which must
answer the status it prints."""

import os
import pathlib
import re
import subprocess
import time

from conftest import Daemon

ROOT = pathlib.Path(__file__).resolve().parents[3]


def curl_lines():
    """Lines of ```sh blocks that start with `curl` (continuations joined)."""
    text = (ROOT / "README.md").read_text()
    lines = []
    for block in re.findall(r"```sh\n(.*?)```", text, re.S):
        joined = block.replace("\\\n", " ")
        lines += [l.strip() for l in joined.splitlines() if l.strip().startswith("curl ")]
    return lines


def test_the_readme_has_curl_lines():
    assert len(curl_lines()) >= 15


def test_every_readme_curl_line_works_as_printed():
    d = Daemon("--sim", "16")
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":16' in b, "16 joints online")
        env = {**os.environ, "API": d.url + "/api/v1", "J": "content-type: application/json"}
        failures = []
        for line in curl_lines():
            # The README's daemon listens on 8080; this one on a free port.
            line = line.replace("http://127.0.0.1:8080", d.url)
            # Run once, as printed; `curl` records the response head so the
            # status can be read without running the line twice.
            head = f"/tmp/jointd-readme-head-{os.getpid()}"
            wrapped = f'curl() {{ command curl -D {head} "$@"; }}\n{line}'
            ran = subprocess.run(["bash", "-o", "pipefail", "-c", wrapped], env=env,
                                 capture_output=True, text=True, timeout=30)
            status = open(head).read().split(" ")[1] if os.path.exists(head) else "none"
            if os.path.exists(head):
                os.remove(head)
            expected = "422" if '"position_deg": 300' in line else "2"
            if not status.startswith(expected) or ran.returncode != 0 or not ran.stdout.strip():
                failures.append(f"{line}\n  -> {status} rc={ran.returncode} {ran.stdout[:200]}{ran.stderr[:200]}")
            if "/enable" in line:
                # A person reads the next line; the README says the first
                # enable aligns the encoder for about a second.
                time.sleep(1.2)
        assert not failures, "\n".join(failures)
    finally:
        d.stop()


def test_the_readme_python_example_runs(daemon):
    text = (ROOT / "README.md").read_text()
    section = text.split("### Python", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    code = code.replace("http://127.0.0.1:8080", daemon.url)
    import sys
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "(1, " in out.stdout, out.stdout
