"""The client keeps up with the daemon: a method for every operation of
openapi/openapi.json, schema types generated from the same document, and
mypy --strict clean on the package and the examples."""

import json
import pathlib
import subprocess
import sys

from jointd_client import Jointd

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[2]
DOC = ROOT / "openapi" / "openapi.json"


def operation_ids():
    doc = json.loads(DOC.read_text())
    return {op["operationId"] for ops in doc["paths"].values() for m, op in ops.items()
            if m in ("get", "put", "post", "patch", "delete")}


def client_operations():
    tagged = {}
    for name in dir(Jointd):
        for op in getattr(getattr(Jointd, name), "operations", ()):
            assert op not in tagged, f"{op} is tagged on both {tagged[op]} and {name}"
            tagged[op] = name
    return tagged


def test_every_operation_has_a_client_method():
    missing = sorted(operation_ids() - client_operations().keys())
    assert not missing, f"operations without a client method: {missing}"


def test_no_method_names_an_operation_the_daemon_does_not_have():
    stale = sorted(client_operations().keys() - operation_ids())
    assert not stale, f"methods tagged with unknown operations: {stale}"


def test_the_schema_module_is_generated_from_the_current_document():
    r = subprocess.run([sys.executable, str(HERE.parent / "gen_schema.py"), "--check"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_mypy_strict_passes_on_the_package_and_the_examples():
    r = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--no-incremental",
                        str(HERE.parent / "jointd_client"), str(ROOT / "examples" / "teleop.py")],
                       capture_output=True, text=True, cwd=HERE.parent)
    assert r.returncode == 0, r.stdout + r.stderr
