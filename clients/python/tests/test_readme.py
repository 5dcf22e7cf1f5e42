"""Every `curl` line of the README and of the docs pages that continue its
walkthrough, in order, as printed, against the daemon of the README's first
command (`--sim 16`, here on a free port): each must answer 2xx, except the
line docs/rest.md shows failing, which must answer the status it prints.
The `until curl ...; do sleep 0.2; done` lines that wait for a joint to run
are run too: they must end (within 30 s) on a 2xx."""

import json
import os
import pathlib
import re
import subprocess

from conftest import Daemon

ROOT = pathlib.Path(__file__).resolve().parents[3]


# The README's walkthrough, then the pages that go on from where it stops.
PAGES = ["README.md", "docs/rest.md", "docs/motion.md", "docs/recordings.md"]


def curl_lines():
    """Lines of ```sh blocks that start with `curl` or `until curl`
    (continuations joined), page after page."""
    lines = []
    for page in PAGES:
        text = (ROOT / page).read_text()
        for block in re.findall(r"```sh\n(.*?)```", text, re.S):
            joined = block.replace("\\\n", " ")
            lines += [l.strip() for l in joined.splitlines()
                      if l.strip().startswith(("curl ", "until curl "))]
    return lines


def test_the_readme_has_curl_lines():
    assert len(curl_lines()) >= 15
    # The README's own walkthrough waits for the joint before moving it.
    readme = [l for l in curl_lines() if l in (ROOT / "README.md").read_text()]
    assert any(l.startswith("until curl") for l in readme)


def test_every_readme_curl_line_works_as_printed():
    d = Daemon("--sim", "16")
    try:
        d.wait("/api/v1/buses/sim0", lambda b: b'"devices_online":16' in b, "16 joints online")
        # And every joint's state read once (INFO_01): the bus takes a joint
        # whose first state read shows it enabled for one enabled before the
        # daemon started (on_start), so the walkthrough's enable must come after.
        d.wait("/api/v1/buses/sim0/devices",
               lambda b: all(dev.get("state") for dev in json.loads(b)["devices"]),
               "every joint's state read")
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
            # A wait prints nothing; every other line shows its answer.
            printed = line.startswith("until ") or ran.stdout.strip()
            if not status.startswith(expected) or ran.returncode != 0 or not printed:
                failures.append(f"{line}\n  -> {status} rc={ran.returncode} {ran.stdout[:200]}{ran.stderr[:200]}")
        assert not failures, "\n".join(failures)
    finally:
        d.stop()


def test_the_readme_python_example_runs(daemon):
    text = (ROOT / "docs" / "rest.md").read_text()
    section = text.split("## Python", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    code = code.replace("http://127.0.0.1:8080", daemon.url)
    import sys
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "(1, " in out.stdout, out.stdout
