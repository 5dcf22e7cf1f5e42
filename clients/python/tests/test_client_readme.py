"""The client README's Python example runs as printed, against a daemon
found through JOINTD_URL, and does what its comments say."""

import contextlib
import io
import pathlib
import re

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_the_readme_example_runs(daemon, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    assert len(blocks) == 1, "one Python example in the client README"
    monkeypatch.setenv("JOINTD_URL", daemon.url)
    monkeypatch.delenv("JOINTD_TOKEN", raising=False)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(blocks[0], str(README), "exec"), {})
    lines = out.getvalue().splitlines()
    assert lines[0] == "['sim0']"
    state, angle = lines[1].split()
    assert state == "done" and abs(float(angle) - 30) < 2, lines
