"""Fixtures of the SDK end-to-end tests (tests/e2e/test_sdk_typescript.py, test_sdk_csharp.py).

``sdk_servers`` (session scope): two real ``quadloc serve`` processes on free loopback ports,
started once for the TypeScript and C# suites: an open one (demo map ``chess``) and one with
API keys (a read+write key and a read key), room for one tracking session and a 20 kB body
limit, so that 401, 403, 413 and session-capacity can be answered for real.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import run_live_server


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
