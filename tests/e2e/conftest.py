"""Fixtures of the SDK end-to-end tests (tests/e2e/test_sdk_typescript.py, test_sdk_csharp.py,
and the TypeScript / C# quick starts of tests/e2e/test_docs_examples.py).

``sdk_servers`` (session scope): two real ``quadloc serve`` processes on free loopback ports,
started once for the TypeScript and C# suites: an open one (demo map ``chess``) and one with
API keys (a read+write key and a read key), room for one tracking session and a 20 kB body
limit, so that 401, 403, 413 and session-capacity can be answered for real.

``ts_package`` (session scope): sdk/typescript with its dev dependencies (``npm ci`` from the
committed lock, only when node_modules is older than the lock) and ``npm run build`` done;
skips when node / npm are absent or the npm registry cannot be reached for the first install.
``csharp_build`` (session scope): sdk/csharp/build/ compiled by sdk/csharp/build.sh (Mono's
mcs); skips when mono is absent.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import run_live_server

REPO = Path(__file__).resolve().parents[2]
TS_PACKAGE = REPO / "sdk" / "typescript"
CSHARP = REPO / "sdk" / "csharp"
NODE, NPM = shutil.which("node"), shutil.which("npm")
MCS, MONO = shutil.which("mcs"), shutil.which("mono")
NO_NODE = "node / npm are not installed (apt-get install -y nodejs npm)"
NO_MONO = "mono is not installed (apt-get install -y mono-mcs libmono-system-net-http4.0-cil)"
_NETWORK_ERRORS = re.compile(r"ENOTFOUND|ECONNREFUSED|ETIMEDOUT|EAI_AGAIN|ECONNRESET|network")


@dataclass(frozen=True)
class SdkServers:
    url: str
    keyed_url: str
    key_rw: str
    key_read: str

    def env(self) -> dict[str, str]:
        """The variables the SDK suites read (sdk/typescript/test/live.test.ts, sdk/csharp)."""
        return {"QUADLOC_URL": self.url, "QUADLOC_KEYED_URL": self.keyed_url,
                "QUADLOC_KEY_RW": self.key_rw, "QUADLOC_KEY_READ": self.key_read}


@pytest.fixture(scope="session")
def sdk_servers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SdkServers]:
    key_rw, key_read = "sdk-test-read-write-key", "sdk-test-read-key"
    keys = ",".join(f"{hashlib.sha256(k.encode()).hexdigest()}:{scopes}"
                    for k, scopes in ((key_rw, "read+write"), (key_read, "read")))
    root: Path = tmp_path_factory.mktemp("sdk_servers")
    with run_live_server(root / "open") as url, run_live_server(
            root / "keyed", {"QUADLOC_API_KEYS": keys, "QUADLOC_MAX_SESSIONS": "1",
                             "QUADLOC_MAX_BODY_BYTES": "20000"}) as keyed_url:
        yield SdkServers(url, keyed_url, key_rw, key_read)


def _run(cmd: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


@pytest.fixture(scope="session")
def ts_package() -> Path:
    """sdk/typescript with node_modules installed and dist/ + build-test/ built."""
    if NODE is None or NPM is None:
        pytest.skip(NO_NODE)
    stamp = TS_PACKAGE / "node_modules" / ".package-lock.json"
    lock = TS_PACKAGE / "package-lock.json"
    if not stamp.exists() or stamp.stat().st_mtime < lock.stat().st_mtime:
        r = _run([NPM, "ci", "--no-audit", "--no-fund", "--loglevel=error"], TS_PACKAGE, 300)
        if r.returncode != 0:
            if _NETWORK_ERRORS.search(r.stderr):
                pytest.skip(f"npm ci could not reach the registry: {r.stderr[-500:]}")
            pytest.fail(f"npm ci failed:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
    r = _run([NPM, "run", "build", "--silent"], TS_PACKAGE, 300)
    assert r.returncode == 0, f"tsc failed:\n{r.stdout[-4000:]}\n{r.stderr[-2000:]}"
    assert (TS_PACKAGE / "dist" / "index.js").exists()
    return TS_PACKAGE


@pytest.fixture(scope="session")
def csharp_build() -> Path:
    """sdk/csharp/build/ with QuadLoc.Client.dll and the tests' executable."""
    if MCS is None or MONO is None:
        pytest.skip(NO_MONO)
    r = _run(["bash", str(CSHARP / "build.sh")], CSHARP, 300)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    return CSHARP / "build"
