"""In a real headless browser (Debian's chromium driven by playwright, never a downloaded
browser): the inspector page draws a localization, and /docs and /redoc render, all with every
non-loopback request blocked and recorded (none may be attempted).

Skips with a message when chromium or the playwright package is absent. CI needs
``apt-get install -y chromium`` (the playwright wheel comes with the dev extra).
Set ``QUADLOC_WRITE_SCREENSHOTS=1`` to refresh ``docs/img/inspector.png``.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest

REPO = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Root in a container needs --no-sandbox; the rest keeps chromium from calling home.
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--disable-dev-shm-usage"]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.browser,
    pytest.mark.skipif(CHROMIUM is None,
                       reason="chromium is not installed (apt-get install -y chromium)"),
]
sync_api = pytest.importorskip("playwright.sync_api",
                               reason="the playwright package is not installed (dev extra)")


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


class OfflinePage:
    """A page whose requests outside the server's loopback origin are aborted and recorded;
    failed same-origin requests and console errors are recorded too."""

    def __init__(self, browser: object, base: str) -> None:
        self.base = base
        self.external: list[str] = []
        self.failed: list[str] = []
        self.console_errors: list[str] = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})  # type: ignore[attr-defined]
        self.page.set_default_timeout(30_000)
        self.page.route("**/*", self._route)
        # Same-origin failures only: a request the page's CSP blocked never reached the network
        # (route() above saw every request that would have, and records them as external).
        self.page.on("requestfailed", lambda r: self.failed.append(r.url)
                     if r.url.startswith(base) else None)
        self.page.on("console", self._console)

    def _route(self, route: object) -> None:
        url = route.request.url  # type: ignore[attr-defined]
        host = urlsplit(url).hostname or ""
        if url.startswith(("data:", "blob:")) or host in {"127.0.0.1", "localhost", "::1"}:
            route.continue_()  # type: ignore[attr-defined]
        else:
            self.external.append(url)
            route.abort()  # type: ignore[attr-defined]

    def _console(self, msg: object) -> None:
        if msg.type == "error":  # type: ignore[attr-defined]
            self.console_errors.append(msg.text)  # type: ignore[attr-defined]

    def assert_offline_clean(self) -> None:
        assert self.external == [], f"external requests attempted: {self.external}"
        assert self.failed == [], f"requests failed: {self.failed}"
        # The only tolerated console error: our CSP blocking ReDoc's remote logo (no request).
        other = [e for e in self.console_errors if "Content Security Policy" not in e]
        assert other == [], other


def test_inspector_draws_a_localization_offline(browser: object, live_server: str,
                                                tmp_path: Path) -> None:
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector("#map option[value=chess]", state="attached")
    page.click("#load-example")
    sync_api.expect(page.locator("#request")).to_have_value(re.compile("detections"))
    page.click("#localize")
    page.wait_for_selector("#status[data-state=done]")
    status = page.inner_text("#status")
    assert status.startswith("Localized"), status
    # The overlay: every detection drawn, all 9 matched (the demo frame), the matched
    # objects' projections drawn solid, and the 3D view drew the map's objects.
    n_det = page.locator("#overlay svg ellipse.detection").count()
    n_inliers = page.locator("#overlay svg ellipse.detection.inlier").count()
    n_matched = page.locator("#overlay svg ellipse.projection.matched").count()
    assert n_det == 9 and n_inliers == 9 and n_matched == 9, (n_det, n_inliers, n_matched)
    assert page.locator("#inliers tbody tr").count() == 9
    assert int(page.get_attribute("#view3d", "data-drawn") or 0) > 0
    # The canvas is not blank: some pixels were painted.
    painted = page.evaluate("""() => {
        const c = document.getElementById('view3d');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n; }""")
    assert painted > 1000, painted
    shot = tmp_path / "inspector.png"
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 20_000
    if os.environ.get("QUADLOC_WRITE_SCREENSHOTS") == "1":
        shutil.copy(shot, REPO / "docs" / "img" / "inspector.png")
    op.assert_offline_clean()
    page.close()


def test_inspector_shows_request_errors(browser: object, live_server: str) -> None:
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector("#map option[value=chess]", state="attached")
    page.fill("#request", '{"camera": {"fx": -1}, "detections": []}')
    page.click("#localize")
    page.wait_for_selector("#status[data-state=error]")
    assert "camera.fx" in page.inner_text("#status")
    page.close()


def test_swagger_ui_renders_offline(browser: object, live_server: str) -> None:
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/docs")
    page.wait_for_selector(".opblock")
    assert page.locator(".opblock").count() >= 8
    assert "/v1/maps/{map_id}/localize" in page.inner_text("#swagger-ui")
    op.assert_offline_clean()
    page.close()


def test_redoc_renders_offline(browser: object, live_server: str) -> None:
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/redoc")
    page.wait_for_selector("h2:has-text('Localize one frame')")
    assert "world_from_camera" in page.inner_text("body")
    op.assert_offline_clean()
    page.close()
