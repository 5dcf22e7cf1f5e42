"""docs/tls-proxy.md's nginx config, run as written (only its ports and
paths changed) in front of a daemon with a token: the dashboard, a
token-guarded read, a write from the proxy's own origin, a foreign
origin refused, and telemetry over wss://, all through nginx. Needs
`nginx` and `openssl` (CI installs them)."""

import asyncio
import http.client
import json
import os
import pathlib
import re
import shutil
import socket
import ssl
import subprocess
import time

import pytest
import websockets

from conftest import ROOT, Daemon

DOC = ROOT / "docs" / "tls-proxy.md"
TOKEN = "proxy-test-token"
NAME = "robot-pc"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def doc_config():
    """The page's nginx block, as a user copies it."""
    blocks = re.findall(r"```nginx\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 1, "docs/tls-proxy.md holds one nginx block"
    return blocks[0]


def adapted(config, port, upstream, tls):
    """The block with this run's port, upstream and certificate paths:
    every other line as the page has it."""
    swaps = [
        ("listen 8443 ssl;", f"listen 127.0.0.1:{port} ssl;"),
        ("proxy_pass http://127.0.0.1:8080;", f"proxy_pass {upstream};"),
        ("/etc/jointd/tls/cert.pem", str(tls / "cert.pem")),
        ("/etc/jointd/tls/key.pem", str(tls / "key.pem")),
    ]
    for old, new in swaps:
        assert old in config, f"the page's config lost `{old}`"
        config = config.replace(old, new)
    return config


@pytest.fixture()
def proxied(tmp_path):
    nginx = shutil.which("nginx") or "/usr/sbin/nginx"
    assert os.path.exists(nginx), "nginx is needed (apt-get install nginx-light)"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-subj", f"/CN={NAME}", "-addext", f"subjectAltName=DNS:{NAME},IP:127.0.0.1",
                    "-keyout", str(tmp_path / "key.pem"), "-out", str(tmp_path / "cert.pem")],
                   check=True, capture_output=True)
    d = Daemon("--sim", "4", "--token", TOKEN, "--allowed-host", NAME)
    port = free_port()
    tmp_path.chmod(0o755)
    user = "user root;\n" if os.geteuid() == 0 else ""
    (tmp_path / "nginx.conf").write_text(
        f"{user}worker_processes 1;\npid {tmp_path}/nginx.pid;\nerror_log {tmp_path}/error.log;\n"
        f"events {{}}\nhttp {{\naccess_log off;\n"
        # Debian's build puts these under /var/lib/nginx, not ours to write.
        + "".join(f"{kind}_temp_path {tmp_path}/{kind};\n"
                  for kind in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
        + adapted(doc_config(), port, d.url, tmp_path) + "}\n")
    proc = subprocess.Popen([nginx, "-p", str(tmp_path), "-c", str(tmp_path / "nginx.conf"),
                             "-g", "daemon off;"], stderr=subprocess.PIPE, text=True)
    ctx = ssl.create_default_context(cafile=str(tmp_path / "cert.pem"))
    try:
        deadline = time.monotonic() + 20
        while True:
            assert proc.poll() is None, f"nginx exited: {proc.stderr.read()}"
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "nginx never listened"
                time.sleep(0.05)
        d.wait("/healthz", lambda b: True, "the daemon up")
        yield port, ctx, d
    finally:
        proc.terminate()
        proc.wait(10)
        d.stop()


def request(port, ctx, method, path, body=None, headers=None):
    """One HTTPS request through the proxy, by the name a browser would use."""
    conn = http.client.HTTPSConnection("127.0.0.1", port, context=ctx, timeout=10)
    hdrs = {"Host": f"{NAME}:{port}", **(headers or {})}
    data = json.dumps(body).encode() if body is not None else None
    if data is not None:
        hdrs["Content-Type"] = "application/json"
    conn.request(method, path, body=data, headers=hdrs)
    r = conn.getresponse()
    out = r.status, r.read()
    conn.close()
    return out


def test_the_pages_nginx_config_serves_jointd_over_tls(proxied):
    port, ctx, d = proxied
    auth = {"Authorization": f"Bearer {TOKEN}"}
    status, page = request(port, ctx, "GET", "/")
    assert status == 200 and b"<html" in page.lower(), (status, page[:200])
    status, _ = request(port, ctx, "GET", "/api/v1/buses")
    assert status == 401, "the token is still asked for"
    status, body = request(port, ctx, "GET", "/api/v1/buses", headers=auth)
    assert status == 200 and json.loads(body)["buses"][0]["name"] == "sim0", body
    # The dashboard's own origin through the proxy: the Host was kept.
    own = {**auth, "Origin": f"https://{NAME}:{port}"}
    status, body = request(port, ctx, "POST", "/api/v1/buses/sim0/control/enable", {"ids": [1]}, own)
    assert status == 200, body
    foreign = {**auth, "Origin": "https://evil.example"}
    status, body = request(port, ctx, "POST", "/api/v1/buses/sim0/control/disable", {"ids": [1]}, foreign)
    assert status == 403 and b"foreign-origin" in body, (status, body)

    async def telemetry():
        async with websockets.connect(f"wss://127.0.0.1:{port}/api/v1/ws", ssl=ctx,
                                      additional_headers=auth) as ws:
            await ws.send(json.dumps({"type": "subscribe", "seq": 1, "rate_hz": 50}))
            samples = []
            while len(samples) < 5:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
                if msg.get("type") == "telemetry":
                    samples.append(msg)
            return samples

    samples = asyncio.run(telemetry())
    assert [s["seq"] for s in samples] == sorted(s["seq"] for s in samples)
    assert {j["id"] for j in samples[-1]["joints"]} == {1, 2, 3, 4}
