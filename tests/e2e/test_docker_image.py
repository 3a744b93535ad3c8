"""The container image, for real: built with the Docker engine and run with ``--network host``.

Checks (issue 9): non-root uid; no compilers or test tools, size reported; ``/healthz`` and
``/readyz``; the docs' demo frame localizes through the SDK from outside the container; without
API keys the server refuses 0.0.0.0, with keys it enforces them; maps written through the API
survive a container restart on the ``/data`` volume; ``docker stop`` (SIGTERM) ends it within
10 s with no acknowledged write lost; and the docker-compose topology (two replicas sharing
PostgreSQL behind nginx) with host networking: replicas on two ports, the host's PostgreSQL,
the host's nginx with ``deploy/nginx.conf``'s settings.

Marked ``docker``. Skipped, with the reason, when no Docker engine answers (``docker info``) or
no base image can be had. The image under test is ``QUADLOC_TEST_IMAGE`` if set, else built
here from the checkout with ``--build-arg BASE=`` ``QUADLOC_DOCKER_BASE``, or the first present
of ``python:3.11-slim`` and ``quadloc-base:bookworm`` (built by ``deploy/build-base-image.sh``
when debootstrap is installed and we are root). ``deploy/test-image.sh`` runs this module and
prints the measurements (build time, image size, start-to-ready time), which it also writes as
JSON to ``QUADLOC_DOCKER_REPORT`` when set.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import re
import shutil
import socket
import subprocess
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

import quadloc_sdk as sdk
from quadloc_sdk import errors as sdk_errors

pytestmark = [pytest.mark.docker, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
LOCAL_BASE = "quadloc-base:bookworm"
RUN_ID = uuid.uuid4().hex[:8]
READ_WRITE_KEY, READ_KEY = f"rw-{RUN_ID}-secret", f"ro-{RUN_ID}-secret"
API_KEYS = (f"{hashlib.sha256(READ_WRITE_KEY.encode()).hexdigest()}:read+write,"
            f"{hashlib.sha256(READ_KEY.encode()).hexdigest()}:read")
REPORT: dict[str, Any] = {}


def _docker(*args: str, timeout: float = 120, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(["docker", *args], capture_output=True, text=True, timeout=timeout)
    if check and out.returncode != 0:
        raise AssertionError(f"docker {' '.join(args)} -> {out.returncode}\n{out.stderr[-3000:]}")
    return out


def _engine_problem() -> str | None:
    if shutil.which("docker") is None:
        return "no docker client on PATH (install docker.io; docs/deployment.md)"
    try:
        out = subprocess.run(["docker", "info", "--format", "{{.ServerVersion}}"],
                             capture_output=True, text=True, timeout=20)
    except subprocess.TimeoutExpired:
        return "docker info timed out: no Docker engine answering"
    if out.returncode != 0:
        return ("no Docker engine answering (start one: dockerd --iptables=false "
                "--ip6tables=false --bridge=none --data-root DIR &; docs/deployment.md): "
                + out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "")
    return None


def _image_exists(name: str) -> bool:
    return _docker("image", "inspect", name, check=False, timeout=30).returncode == 0


def _base_image() -> str:
    wanted = os.environ.get("QUADLOC_DOCKER_BASE")
    if wanted:
        return wanted
    for name in ("python:3.11-slim", LOCAL_BASE):
        if _image_exists(name):
            return name
    if shutil.which("debootstrap") and os.geteuid() == 0:
        out = subprocess.run(["bash", str(REPO / "deploy" / "build-base-image.sh"), LOCAL_BASE],
                             capture_output=True, text=True, timeout=600)
        if out.returncode == 0:
            return LOCAL_BASE
        pytest.skip(f"could not build the local base image: {out.stderr[-500:]}")
    pytest.skip("no base image: python:3.11-slim cannot be pulled here and "
                f"{LOCAL_BASE} is absent (run deploy/build-base-image.sh as root)")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_ready(base: str, name: str, timeout_s: float = 90.0) -> float:
    """Seconds until ``/readyz`` answers 200; fails with the container's log otherwise."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        state = _docker("inspect", "-f", "{{.State.Running}}", name, check=False).stdout.strip()
        if state == "false":
            logs = _docker("logs", name, check=False)
            raise AssertionError(f"container {name} exited:\n{logs.stdout[-2000:]}"
                                 f"{logs.stderr[-2000:]}")
        try:
            if httpx.get(f"{base}/readyz", timeout=2.0).status_code == 200:
                return time.monotonic() - t0
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    logs = _docker("logs", name, check=False)
    raise AssertionError(f"{name} not ready in {timeout_s} s:\n{logs.stderr[-3000:]}")


@pytest.fixture(scope="module")
def image() -> Iterator[str]:
    problem = _engine_problem()
    if problem:
        pytest.skip(problem)
    given = os.environ.get("QUADLOC_TEST_IMAGE")
    if given:
        yield given
        return
    base = _base_image()
    tag = f"quadloc:test-{RUN_ID}"
    t0 = time.monotonic()
    out = subprocess.run(["docker", "build", "--network", "host", "--build-arg", f"BASE={base}",
                          "-t", tag, str(REPO)], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    REPORT.update(base=base, build_seconds=round(time.monotonic() - t0, 1),
                  build_command=f"docker build --network host --build-arg BASE={base} -t {tag} .")
    try:
        yield tag
    finally:
        if os.environ.get("QUADLOC_DOCKER_KEEP_IMAGE") != "1":
            _docker("image", "rm", "-f", tag, check=False)
        report_path = os.environ.get("QUADLOC_DOCKER_REPORT")
        if report_path:
            Path(report_path).write_text(json.dumps(REPORT, indent=2) + "\n")


class Container:
    """One ``docker run -d --network host`` of the image, on its own port."""

    def __init__(self, image: str, env: dict[str, str], volume: str | None = None,
                 name: str | None = None, port: int | None = None) -> None:
        self.image, self.env, self.volume = image, dict(env), volume
        self.port = port or _free_port()
        self.name = name or f"quadloc-test-{RUN_ID}-{self.port}"
        self.base = f"http://127.0.0.1:{self.port}"

    def run(self, *extra: str) -> None:
        args = ["run", "-d", "--name", self.name, "--network", "host",
                "-e", f"QUADLOC_PORT={self.port}"]
        for k, v in self.env.items():
            args += ["-e", f"{k}={v}"]
        if self.volume:
            args += ["-v", f"{self.volume}:/data"]
        _docker(*args, *extra, self.image)

    def remove(self) -> None:
        _docker("rm", "-f", "-v", self.name, check=False)  # -v: its anonymous /data volume


@pytest.fixture(scope="module")
def volume(image: str) -> Iterator[str]:
    name = f"quadloc-test-data-{RUN_ID}"
    _docker("volume", "create", name)
    yield name
    _docker("volume", "rm", "-f", name, check=False)


@pytest.fixture(scope="module")
def server(image: str, volume: str) -> Iterator[Container]:
    c = Container(image, {"QUADLOC_API_KEYS": API_KEYS}, volume=volume)
    c.run()
    try:
        REPORT["start_to_ready_seconds"] = round(_wait_ready(c.base, c.name), 2)
        yield c
    finally:
        c.remove()


def _client(c: Container, key: str | None = READ_WRITE_KEY) -> sdk.QuadLocClient:
    return sdk.QuadLocClient(c.base, api_key=key)


# --------------------------------------------------------------------------- the image itself


def test_image_runs_as_non_root_and_is_lean(image: str) -> None:
    user = _docker("image", "inspect", "-f", "{{.Config.User}}", image).stdout.strip()
    assert user and user.split(":")[0] not in ("", "0", "root"), user
    uid = _docker("run", "--rm", "--network", "host", image, "id", "-u").stdout.strip()
    assert uid == "10001"
    probe = ("import importlib.util as u, shutil; "
             "print([t for t in ('gcc', 'cc', 'c++', 'make', 'apt-get') if shutil.which(t)], "
             "[m for m in ('pytest', 'hypothesis', 'ruff', 'schemathesis', 'setuptools') "
             "if u.find_spec(m)])")
    found = _docker("run", "--rm", "--network", "host", image, "python", "-c", probe).stdout
    tools, modules = found.strip().split("] [")
    assert "gcc" not in tools and "cc'" not in tools and "make" not in tools, found
    assert modules.strip("[]") == "", f"test tools / build backend in the image: {found}"
    size = int(_docker("image", "inspect", "-f", "{{.Size}}", image).stdout.strip())
    REPORT["image_size_mb"] = round(size / 1e6)
    assert size < 800e6, f"image is {size / 1e6:.0f} MB"


def test_refuses_0000_without_api_keys(image: str) -> None:
    c = Container(image, {})
    c.run()
    try:
        deadline = time.monotonic() + 60
        while _docker("inspect", "-f", "{{.State.Running}}", c.name).stdout.strip() == "true":
            assert time.monotonic() < deadline, "server without keys kept running on 0.0.0.0"
            time.sleep(0.2)
        code = int(_docker("inspect", "-f", "{{.State.ExitCode}}", c.name).stdout.strip())
        logs = _docker("logs", c.name)
        assert code != 0
        assert "QUADLOC_API_KEYS" in logs.stderr + logs.stdout
        with pytest.raises(httpx.TransportError):
            httpx.get(f"{c.base}/healthz", timeout=1.0)
    finally:
        c.remove()


def test_health_readiness_and_keys_enforced(server: Container) -> None:
    assert httpx.get(f"{server.base}/healthz", timeout=5).status_code == 200
    ready = httpx.get(f"{server.base}/readyz", timeout=5)
    assert ready.status_code == 200, ready.text
    assert httpx.get(f"{server.base}/v1/maps", timeout=5).status_code == 401
    wrong = {"Authorization": "Bearer not-a-key"}
    assert httpx.get(f"{server.base}/v1/maps", headers=wrong, timeout=5).status_code == 401
    with _client(server, READ_KEY) as ro:
        assert "chess" in {m.map_id for m in ro.list_maps()}
        with pytest.raises(sdk_errors.Forbidden):
            ro.delete_map("chess")


def test_demo_frame_localizes_through_the_sdk(server: Container) -> None:
    from quadloc.factors.rotations import rotation_angle
    from quadloc.service.schemas.examples import EXAMPLE_TRUE_WORLD_FROM_CAMERA

    body = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
    with _client(server, READ_KEY) as client:
        answer = client.localize("chess", body)
    assert answer.localized, answer
    got = np.array(answer.world_from_camera.matrix)
    truth = np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)
    assert np.linalg.norm(got[:3, 3] - truth[:3, 3]) < 0.05
    assert np.degrees(rotation_angle(got[:3, :3], truth[:3, :3])) < 2.0


# --------------------------------------------------------------------------- persistence, stop


def _office(map_id: str, name: str = "Office") -> dict[str, Any]:
    doc = json.loads((REPO / "docs" / "examples" / "office_map.json").read_text())
    return {**doc, "map_id": map_id, "name": name}


def test_maps_survive_a_restart_on_the_data_volume(image: str, volume: str,
                                                   server: Container) -> None:
    with _client(server) as client:
        created = client.create_map(_office(f"office-{RUN_ID}"))
    _docker("restart", "-t", "10", server.name)
    _wait_ready(server.base, server.name)
    with _client(server) as client:
        again = client.get_map(created.map_id)
    assert (again.version, again.content_hash) == (created.version, created.content_hash)
    # A new container on the same volume (not the old container's layer) sees it too.
    fresh = Container(image, {"QUADLOC_API_KEYS": API_KEYS}, volume=volume)
    _docker("stop", "-t", "10", server.name)
    fresh.run()
    try:
        _wait_ready(fresh.base, fresh.name)
        with _client(fresh) as client:
            assert client.get_map(created.map_id).content_hash == created.content_hash
    finally:
        fresh.remove()
        _docker("start", server.name)
        _wait_ready(server.base, server.name)


def test_sigterm_stops_within_10_s_without_losing_acknowledged_writes(
        image: str, volume: str) -> None:
    c = Container(image, {"QUADLOC_API_KEYS": API_KEYS}, volume=volume)
    c.run()
    acked: list[tuple[int, str]] = []
    stop_writing = threading.Event()
    map_id = f"stop-{RUN_ID}"
    try:
        _wait_ready(c.base, c.name)
        with _client(c) as client:
            first = client.create_map(_office(map_id, "v1"))
        acked.append((first.version, first.content_hash))

        def writer() -> None:
            with httpx.Client(base_url=c.base, timeout=10,
                              headers={"Authorization": f"Bearer {READ_WRITE_KEY}"}) as http:
                version = first.version
                while not stop_writing.is_set():
                    try:
                        r = http.put(f"/v1/maps/{map_id}", json=_office(map_id, f"v{version + 1}"),
                                     headers={"If-Match": f'"{acked[-1][1]}"'})
                    except httpx.TransportError:
                        return  # the server went away mid-request: not acknowledged
                    if r.status_code != 200:
                        return
                    version = r.json()["version"]
                    acked.append((version, r.json()["content_hash"]))

        thread = threading.Thread(target=writer)
        thread.start()
        time.sleep(1.5)  # writes in flight
        t0 = time.monotonic()
        _docker("stop", "-t", "10", c.name, timeout=60)
        stop_seconds = time.monotonic() - t0
        stop_writing.set()
        thread.join(30)
        exit_code = int(_docker("inspect", "-f", "{{.State.ExitCode}}", c.name).stdout.strip())
        REPORT["sigterm_stop_seconds"] = round(stop_seconds, 2)
        REPORT["writes_acknowledged_before_stop"] = len(acked)
        assert stop_seconds < 10, f"docker stop took {stop_seconds:.1f} s"
        assert exit_code == 0, f"exit code {exit_code} (137 = killed after the grace period)"
        assert len(acked) > 3, "no writes were in flight: the check proved nothing"
        _docker("start", c.name)
        _wait_ready(c.base, c.name)
        with _client(c) as client:
            latest = client.get_map(map_id)
            assert latest.version >= acked[-1][0]
            for version, content_hash in acked[-5:]:
                assert client.get_map(map_id, version=version).content_hash == content_hash
    finally:
        stop_writing.set()
        c.remove()


# --------------------------------------------------------------------------- compose topology


def _postgres_admin_url() -> str:
    return os.environ.get("QUADLOC_TEST_POSTGRES_ADMIN", "postgresql://postgres@127.0.0.1:5432/test")


def test_two_replicas_share_postgres_behind_nginx_with_host_networking(image: str,
                                                                       tmp_path: Path) -> None:
    """docker-compose.yml's topology without a bridge network: replicas on two host ports
    against the host's PostgreSQL, nginx (the host's binary, deploy/nginx.conf with the
    upstreams rewritten to those ports) in front."""
    import psycopg

    nginx = shutil.which("nginx") or ("/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists()
                                      else None)
    if nginx is None:
        pytest.skip("nginx not installed (apt-get install nginx-light)")
    admin = _postgres_admin_url()
    try:
        conn = psycopg.connect(admin, autocommit=True, connect_timeout=3)
    except psycopg.OperationalError as exc:
        pytest.skip(f"no PostgreSQL at {admin}: {exc}")
    db = f"quadloc_docker_{RUN_ID}"
    conn.execute(f'CREATE DATABASE "{db}"')
    url = re.sub(r"/[^/]*$", f"/{db}", admin)
    replicas = [Container(image, {"QUADLOC_API_KEYS": API_KEYS, "QUADLOC_DATABASE_URL": url})
                for _ in range(2)]
    proxy_port = _free_port()
    conf = (REPO / "deploy" / "nginx.conf").read_text()
    conf = re.sub(r"server quadloc-1:8000", f"server 127.0.0.1:{replicas[0].port}", conf)
    conf = re.sub(r"server quadloc-2:8000", f"server 127.0.0.1:{replicas[1].port}", conf)
    conf = conf.replace("listen 8080;", f"listen 127.0.0.1:{proxy_port};")
    conf = conf.replace("/tmp/", f"{tmp_path}/")
    conf = conf.replace("access_log /dev/stdout quadloc;",
                        f"access_log {tmp_path}/access.log quadloc;")
    conf = conf.replace("error_log /dev/stderr warn;", f"error_log {tmp_path}/error.log warn;")
    (tmp_path / "nginx.conf").write_text(conf)
    proxy = None
    try:
        for r in replicas:
            r.run()
        for r in replicas:
            _wait_ready(r.base, r.name)
        proxy = subprocess.Popen([nginx, "-p", str(tmp_path), "-c", str(tmp_path / "nginx.conf"),
                                  "-g", "daemon off;", "-e", str(tmp_path / "error.log")],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        front = f"http://127.0.0.1:{proxy_port}"
        deadline = time.monotonic() + 20
        while True:
            try:
                if httpx.get(f"{front}/nginx-health", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert proxy.poll() is None, proxy.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "nginx did not start"
            time.sleep(0.1)
        with sdk.QuadLocClient(front, api_key=READ_WRITE_KEY) as client:
            created = client.create_map(_office(f"shared-{RUN_ID}"))
            for _ in range(20):
                client.get_map(created.map_id)
            body = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
            assert client.localize("chess", body).localized
        for r in replicas:  # each replica sees the write made through the proxy
            with _client(r, READ_KEY) as direct:
                assert direct.get_map(created.map_id).content_hash == created.content_hash
        upstreams = set(re.findall(r"upstream=(127\.0\.0\.1:\d+)",
                                   (tmp_path / "access.log").read_text()))
        assert upstreams == {f"127.0.0.1:{r.port}" for r in replicas}, upstreams
        _docker("stop", "-t", "10", replicas[0].name)  # one replica down: still served
        with sdk.QuadLocClient(front, api_key=READ_KEY) as client:
            for _ in range(5):
                assert client.get_map(created.map_id).version == 1
    finally:
        if proxy is not None:
            proxy.terminate()
            proxy.wait(10)
        for r in replicas:
            r.remove()
        conn.execute(f'DROP DATABASE IF EXISTS "{db}" WITH (FORCE)')
        conn.close()


def test_compose_stack_with_docker_compose(image: str) -> None:
    """docker-compose.yml itself (bridge network, service names, PostgreSQL, nginx), with local
    stand-ins for the registry images (deploy/compose-local.sh)."""
    if shutil.which("docker-compose") is None and _docker("compose", "version", check=False,
                                                          timeout=20).returncode != 0:
        pytest.skip("no docker-compose / docker compose installed")
    port = _free_port()
    env = {**os.environ, "QUADLOC_API_KEYS": API_KEYS, "QUADLOC_PROXY_PORT": str(port),
           "QUADLOC_COMPOSE_PROJECT": f"quadloctest{RUN_ID}"}
    script = ["bash", str(REPO / "deploy" / "compose-local.sh")]

    def compose(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
        return subprocess.run([*script, *args], env=env, capture_output=True, text=True,
                              timeout=timeout)

    t0 = time.monotonic()
    up = compose("up")
    try:
        assert up.returncode == 0, up.stdout[-2000:] + up.stderr[-3000:]
        REPORT["compose_up_seconds"] = round(time.monotonic() - t0, 1)
        front = f"http://127.0.0.1:{port}"
        with sdk.QuadLocClient(front, api_key=READ_WRITE_KEY) as client:
            assert client.readyz()
            created = client.create_map(_office(f"compose-{RUN_ID}"))
            for _ in range(20):
                assert client.get_map(created.map_id).content_hash == created.content_hash
            body = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
            assert client.localize("chess", body).localized
            # map builds run on the stack's workers (the replicas only queue them)
            recording = json.loads(gzip.decompress(
                (REPO / "docs" / "examples" / "room_recording.json.gz").read_bytes()))
            t1 = time.monotonic()
            job = client.build_map(recording, map_id=f"compose-room-{RUN_ID}", timeout_s=300)
            REPORT["compose_build_seconds"] = round(time.monotonic() - t1, 1)
            assert job.status == "succeeded" and job.map_version == 1
        workers = compose("compose", "logs", "--no-color", "worker", timeout=60).stdout
        assert f"job_id='{job.job_id}'" in workers, "the build did not run on a worker"
        logs = compose("compose", "logs", "--no-color", "proxy", timeout=60).stdout
        upstreams = set(re.findall(r"upstream=([\d.]+:8000)", logs))
        assert len(upstreams) == 2, f"requests did not reach both replicas: {upstreams}"
        assert compose("compose", "stop", "quadloc-1", timeout=60).returncode == 0
        with sdk.QuadLocClient(front, api_key=READ_KEY) as client:
            for _ in range(5):  # the other replica serves, from the shared database
                assert client.get_map(created.map_id).content_hash == created.content_hash
    finally:
        compose("down", timeout=120)
