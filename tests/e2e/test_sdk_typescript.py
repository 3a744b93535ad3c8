"""The TypeScript SDK (sdk/typescript, npm package @quadloc/client), built and tested here:

* ``npm ci`` from the committed lock file (only when node_modules is older than the lock) and
  ``npm run build`` (tsc: the library, then the tests against its declarations);
* the generated wire types are what openapi-typescript makes of docs/openapi.json today;
* node's test runner over the suite: the shared vectors, the client on a mocked fetch, three.js /
  WebXR conventions, and the live tests against two real servers (``sdk_servers``): the demo
  frame localizes, a session tracks the shipped recording, a build job completes, the
  documented errors arrive as their typed errors;
* in headless Chromium (Debian's, driven by playwright; every non-loopback request aborted and
  recorded): a page imports the built module and localizes the demo frame, and the example page
  replays the recording through a tracking session and draws the map in three.js.

Skips, saying why, when node / npm are absent (or the npm registry cannot be reached for the
first install), and the browser part when chromium or playwright is.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

from tests.e2e.conftest import SdkServers

REPO = Path(__file__).resolve().parents[2]
PKG = REPO / "sdk" / "typescript"
NODE = shutil.which("node")
NPM = shutil.which("npm")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(NODE is None or NPM is None,
                       reason="node / npm are not installed (apt-get install -y nodejs npm)"),
]


def _run(cmd: list[str], timeout: float, env: dict[str, str] | None = None
         ) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=PKG, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **(env or {})}, stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def built(ts_package: Path) -> Path:
    return ts_package


def test_generated_types_are_what_the_generator_makes_of_openapi_json(built: Path) -> None:
    r = _run([NODE, "scripts/generate.mjs", "--check"], timeout=120)  # type: ignore[list-item]
    assert r.returncode == 0, r.stderr + r.stdout


def test_node_suite_against_live_servers(built: Path, sdk_servers: SdkServers) -> None:
    r = _run([NODE, "scripts/run-tests.mjs"], timeout=420, env=sdk_servers.env())  # type: ignore[list-item]
    out = r.stdout + r.stderr
    assert r.returncode == 0, out[-8000:]
    counts = {k: int(v) for k, v in re.findall(r"^ℹ (tests|pass|fail|skipped) (\d+)$", out, re.M)}
    # every test ran (the live ones too: nothing skipped), none failed
    assert counts.get("fail") == 0 and counts.get("skipped") == 0, out[-3000:]
    assert counts.get("pass", 0) >= 35, counts
    print(f"node --test: {counts}")


# ----------------------------------------------------------------------------- the browser

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def example_server(built: Path, sdk_servers: SdkServers, tmp_path_factory: pytest.TempPathFactory
                   ) -> Iterator[str]:
    """examples/serve.mjs: the package's pages + the API proxied to the open server."""
    port = _free_port()
    log = tmp_path_factory.mktemp("serve") / "serve.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen([NODE, "examples/serve.mjs", "--quadloc", sdk_servers.url,  # type: ignore[list-item]
                                 "--port", str(port)], cwd=PKG, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        yield base
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    if CHROMIUM is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="the playwright package is not installed (dev extra)")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


class LoopbackPage:
    """A page whose non-loopback requests are aborted and recorded (none may be attempted)."""

    def __init__(self, browser: object) -> None:
        self.external: list[str] = []
        self.errors: list[str] = []
        self.page = browser.new_page(viewport={"width": 1000, "height": 700})  # type: ignore[attr-defined]
        self.page.set_default_timeout(120_000)
        self.page.route("**/*", self._route)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)

    def _route(self, route: object) -> None:
        url = route.request.url  # type: ignore[attr-defined]
        if url.startswith(("data:", "blob:")) or urlsplit(url).hostname in {"127.0.0.1",
                                                                            "localhost"}:
            route.continue_()  # type: ignore[attr-defined]
        else:
            self.external.append(url)
            route.abort()  # type: ignore[attr-defined]


def test_built_module_localizes_the_demo_frame_in_chromium(browser: object,
                                                          example_server: str) -> None:
    import json

    lp = LoopbackPage(browser)
    lp.page.goto(f"{example_server}/test/browser/localize.html")
    lp.page.wait_for_selector("#result:not([data-state=running])")
    text = lp.page.inner_text("#result")
    assert lp.page.get_attribute("#result", "data-state") == "done", text
    result = json.loads(text)
    assert result["localized"] is True and result["inliers"] >= 6, result
    assert abs(result["translation_m"][2] - 0.77) < 0.05, result
    assert result["column_major_matches"] is True
    assert result["error_field"] == "camera.fx"
    assert lp.external == [], lp.external
    # the only console error: the refused request of the error check (422), logged by Chromium
    assert all("422" in e for e in lp.errors), lp.errors
    lp.page.close()


def test_webxr_example_replays_the_recording_and_draws_the_map(browser: object,
                                                              example_server: str,
                                                              tmp_path: Path) -> None:
    lp = LoopbackPage(browser)
    lp.page.goto(f"{example_server}/examples/webxr-replay/")
    lp.page.wait_for_selector("#status[data-state=done], #status[data-state=error]",
                              timeout=180_000)
    status = lp.page.locator("#status")
    assert status.get_attribute("data-state") == "done", status.inner_text()
    frames = int(status.get_attribute("data-frames") or 0)
    tracking = int(status.get_attribute("data-tracking") or 0)
    assert frames == 90 and tracking >= 60, (frames, tracking)
    assert int(status.get_attribute("data-objects") or 0) == 11  # the Chess map's objects
    # the map is anchored where it belongs: the last camera maps onto its ground truth
    assert float(status.get_attribute("data-last-error-m") or 1) < 0.1
    assert int(status.get_attribute("data-painted") or 0) > 5000
    shot = tmp_path / "webxr-replay.png"
    lp.page.screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000
    if os.environ.get("QUADLOC_WRITE_SCREENSHOTS") == "1":
        shutil.copy(shot, REPO / "docs" / "img" / "sdk-webxr-replay.png")
    assert lp.external == [], lp.external
    assert lp.errors == [], lp.errors
    lp.page.close()
