"""The C# SDK (sdk/csharp: QuadLoc.Client for Unity and .NET), compiled with Debian's Mono
compiler (``mcs``, C# 7.2, against System.Net.Http) by ``sdk/csharp/build.sh`` and its tests
run with ``mono``: the shared vectors, the client on a mocked HTTP handler, and the live
scenarios of the TypeScript suite against the two real servers of ``sdk_servers`` (the demo
frame localizes, a session tracks the shipped recording, a build job completes, the documented
errors arrive as their typed exceptions). Skips, saying why, where mono is absent.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.e2e.conftest import SdkServers

REPO = Path(__file__).resolve().parents[2]
CSHARP = REPO / "sdk" / "csharp"
MCS, MONO = shutil.which("mcs"), shutil.which("mono")

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(MCS is None or MONO is None,
                       reason="mono is not installed (apt-get install -y mono-mcs "
                              "libmono-system-net-http4.0-cil)"),
]


def test_csharp_sdk_builds_and_passes_against_live_servers(sdk_servers: SdkServers,
                                                          csharp_build: Path) -> None:
    run = subprocess.run([MONO, str(csharp_build / "QuadLoc.Client.Tests.exe")],  # type: ignore[list-item]
                         capture_output=True, text=True, timeout=420, stdin=subprocess.DEVNULL,
                         env={**os.environ, **sdk_servers.env(), "QUADLOC_REPO": str(REPO)})
    out = run.stdout + run.stderr
    assert run.returncode == 0, out[-8000:]
    m = re.search(r"^(\d+) passed, (\d+) failed(?:, (\d+) skipped)?$", run.stdout, re.M)
    assert m is not None, out[-3000:]
    passed, failed, skipped = int(m.group(1)), int(m.group(2)), int(m.group(3) or 0)
    # every test ran (the live ones too: nothing skipped), none failed
    assert failed == 0 and skipped == 0 and passed >= 14, out[-3000:]
    print(run.stdout.splitlines()[-1])
