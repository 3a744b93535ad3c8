"""The real nginx with deploy/nginx.conf in front of two real replicas (skipped without an
``nginx`` binary): every request of a session reaches the replica that created it (a restarted
replica's 404 ``session-not-found`` is tested in process, tests/service/tracking/test_tracking.py).
Only the upstream addresses, the listen port and the temp paths of the config are rewritten."""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from tests.conftest import REPO_ROOT, _free_port, run_live_server

NGINX = shutil.which("nginx") or next(
    (p for p in ("/usr/sbin/nginx", "/usr/local/sbin/nginx") if Path(p).exists()), None)
pytestmark = pytest.mark.skipif(NGINX is None, reason="no nginx binary")

CAMERA = {"fx": 532.57, "fy": 531.54, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
EYE = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]


def _nginx_conf(text: str, upstreams: dict[str, str], port: int, tmp: Path) -> str:
    for name, addr in upstreams.items():
        text = text.replace(f"{name}:8000", addr)
    text = text.replace("listen 8080;", f"listen 127.0.0.1:{port};")
    text = text.replace("pid /tmp/nginx.pid;", f"pid {tmp}/nginx.pid;")
    text = re.sub(r"/tmp/nginx-", f"{tmp}/nginx-", text)
    text = text.replace("access_log /dev/stdout quadloc;", f"access_log {tmp}/access.log quadloc;")
    text = text.replace("error_log /dev/stderr warn;", f"error_log {tmp}/error.log warn;")
    return "daemon off;\n" + text


def test_sessions_stick_to_their_replica_through_nginx(tmp_path: Path) -> None:
    with run_live_server(tmp_path / "r1", {"QUADLOC_REPLICA_ID": "quadloc-1"}) as b1, \
            run_live_server(tmp_path / "r2", {"QUADLOC_REPLICA_ID": "quadloc-2"}) as b2:
        port = _free_port()
        conf = tmp_path / "nginx.conf"
        conf.write_text(_nginx_conf((REPO_ROOT / "deploy" / "nginx.conf").read_text(),
                                    {"quadloc-1": b1.removeprefix("http://"),
                                     "quadloc-2": b2.removeprefix("http://")}, port, tmp_path))
        proc = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(tmp_path)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        base = f"http://127.0.0.1:{port}"
        try:
            for _ in range(100):
                try:
                    httpx.get(f"{base}/healthz", timeout=1.0)
                    break
                except httpx.TransportError:
                    time.sleep(0.05)
            ids = []
            for _ in range(8):  # least_conn spreads creations over both replicas
                r = httpx.post(f"{base}/v1/maps/chess/sessions", json={"camera": CAMERA})
                assert r.status_code == 201, r.text
                ids.append(r.json()["session_id"])
            # both replicas hold sessions, so a wrong route would show as 404s below
            assert {i.split(".")[0] for i in ids} == {"s-quadloc-1", "s-quadloc-2"}
            for k, sid in enumerate(ids):
                r = httpx.post(f"{base}/v1/sessions/{sid}/frames",
                               json={"odom_from_camera": {"matrix": EYE}, "timestamp": k})
                assert r.status_code == 200, (sid, r.text)
                assert httpx.get(f"{base}/v1/sessions/{sid}").json()["frames"] == 1
        finally:
            proc.terminate()
            proc.wait(timeout=10)
