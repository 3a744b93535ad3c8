"""In a real headless browser (Debian's chromium driven by playwright, never a downloaded
browser): the inspector page draws a localization, and /docs and /redoc render, all with every
non-loopback request blocked and recorded (none may be attempted).

Skips with a message when chromium or the playwright package is absent. CI needs
``apt-get install -y chromium`` (the playwright wheel comes with the dev extra).
Set ``QUADLOC_WRITE_SCREENSHOTS=1`` to refresh ``docs/img/inspector.png``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_REQUEST = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
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


def _painted(page: object) -> int:
    """Pixels of the 3D canvas that something was drawn on."""
    return page.evaluate("""() => {
        const c = document.getElementById('view3d');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n; }""")


def _status_colour(page: object) -> str:
    return page.evaluate(  # type: ignore[attr-defined, no-any-return]
        "() => getComputedStyle(document.getElementById('status')).color")


def _localize(page: object, request: dict, state: str) -> None:
    page.fill("#request", json.dumps(request))  # type: ignore[attr-defined]
    page.click("#localize")  # type: ignore[attr-defined]
    page.wait_for_selector(f"#status[data-state={state}]")  # type: ignore[attr-defined]


def test_inspector_shows_the_map_before_localizing(browser: object, live_server: str) -> None:
    """The 3D view draws the selected map as soon as the page has it (every object of the
    map, counted from the API), without a camera until a localize answers."""
    n_objects = len(httpx.get(f"{live_server}/v1/maps/chess").json()["map"]["objects"])
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector(f"#view3d[data-drawn='{n_objects}']")
    assert page.get_attribute("#view3d", "data-camera") == "false"
    assert _painted(page) > 1000
    assert page.locator("#overlay svg").count() == 0
    _localize(page, EXAMPLE_REQUEST, "done")
    assert page.get_attribute("#view3d", "data-camera") == "true"
    op.assert_offline_clean()
    page.close()


def test_inspector_clears_the_previous_result_after_a_failure(browser: object,
                                                              live_server: str) -> None:
    """A refused request, and a request that is not JSON, leave no trace of the previous
    answer: no overlay, no inlier rows, no camera in the 3D view (the map stays)."""
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector("#map option[value=chess]", state="attached")
    for bad in ('{"camera": {"fx": -1}, "detections": []}', "{not json"):
        _localize(page, EXAMPLE_REQUEST, "done")
        assert page.locator("#overlay svg").count() == 1
        assert page.locator("#inliers tbody tr").count() == len(EXAMPLE_REQUEST["detections"])
        assert page.get_attribute("#view3d", "data-camera") == "true"
        page.fill("#request", bad)
        page.click("#localize")
        page.wait_for_selector("#status[data-state=error]")
        assert page.locator("#overlay svg").count() == 0, bad
        assert page.locator("#inliers tbody tr").count() == 0, bad
        assert page.get_attribute("#view3d", "data-camera") == "false", bad
        assert int(page.get_attribute("#view3d", "data-drawn") or 0) > 0  # the map stays
    page.close()


def test_inspector_shows_not_localized_apart_from_success(browser: object,
                                                          live_server: str) -> None:
    """'Not localized' is a normal answer, but not a success: its status is not drawn in the
    colour of a localized one (nor in the error colour)."""
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector("#map option[value=chess]", state="attached")
    _localize(page, EXAMPLE_REQUEST, "done")
    localized = _status_colour(page)
    two = {**EXAMPLE_REQUEST, "detections": EXAMPLE_REQUEST["detections"][:2]}
    _localize(page, two, "not-localized")
    assert page.inner_text("#status").startswith("Not localized: ")
    not_localized = _status_colour(page)
    page.fill("#request", "{not json")
    page.click("#localize")
    page.wait_for_selector("#status[data-state=error]")
    assert len({localized, not_localized, _status_colour(page)}) == 3
    page.close()


def test_inspector_overlay_labels_neither_overlap_nor_leave_the_frame(browser: object,
                                                                       live_server: str) -> None:
    """The labels of the drawing, as the browser lays them out (``getBBox``): inside the
    image frame and pairwise apart, for the demo frame and for one with detections crowded at
    the right edge (their labels were cut there and drawn over each other)."""
    crowded = {**EXAMPLE_REQUEST, "detections": [
        *EXAMPLE_REQUEST["detections"],
        *({"label": "Chair", "sigma": 0.01,
           "ellipse": {"cx": 636.0, "cy": 60.0 + 4 * k, "a": 3.0, "b": 2.0, "angle": 0.0}}
          for k in range(4))]}
    op = OfflinePage(browser, live_server)
    page = op.page
    page.goto(f"{live_server}/inspector")
    page.wait_for_selector("#map option[value=chess]", state="attached")
    for request in (EXAMPLE_REQUEST, crowded):
        _localize(page, request, "done")
        frame, boxes = page.evaluate("""() => {
            const svg = document.querySelector('#overlay svg');
            const f = svg.querySelector('rect.frame').getBBox();
            const boxes = [...svg.querySelectorAll('text:not(.summary)')].map((t) => {
                const b = t.getBBox();
                return [b.x, b.y, b.x + b.width, b.y + b.height, t.textContent]; });
            return [[f.width, f.height], boxes]; }""")
        assert len(boxes) >= len(request["detections"])
        width, height = frame
        for x0, y0, x1, y1, text in boxes:
            assert x0 >= 0 and x1 <= width and y0 >= 0 and y1 <= height, (text, x0, x1, y0, y1)
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                apart = (a[2] <= b[0] + 0.5 or b[2] <= a[0] + 0.5 or a[3] <= b[1] + 0.5
                         or b[3] <= a[1] + 0.5)
                assert apart, (a, b)
    op.assert_offline_clean()
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


def test_inspector_lists_and_draws_the_candidate_places(browser: object,
                                                        live_server: str) -> None:
    """An ambiguous answer on two exact copies of a room: the candidate table lists each
    alternative of the API's own JSON answer (zone, camera position, confidence), the 3D view
    draws one violet frustum per candidate (violet pixels painted, none before), and a
    localized answer afterwards (hint: room-b) says its zone, hides the table and draws no
    candidate."""
    from tests.support.buildings import two_chess_rooms_document

    doc = two_chess_rooms_document("inspector-two-rooms")
    assert httpx.post(f"{live_server}/v1/maps", json=doc).status_code == 201
    try:
        answer = httpx.post(f"{live_server}/v1/maps/{doc['map_id']}/localize",
                            json=EXAMPLE_REQUEST).json()
        assert answer["reason"] == "ambiguous" and len(answer["alternatives"]) == 2
        op = OfflinePage(browser, live_server)
        page = op.page
        page.goto(f"{live_server}/inspector")
        page.wait_for_selector(f"#map option[value={doc['map_id']}]", state="attached")
        page.select_option("#map", doc["map_id"])
        page.wait_for_selector(f"#view3d[data-drawn='{len(doc['objects'])}']")
        assert not page.is_visible("#candidates")
        violet_before = _violet(page)
        _localize(page, EXAMPLE_REQUEST, "not-localized")
        assert "ambiguous" in page.inner_text("#status")
        assert page.is_visible("#candidates")
        rows = page.eval_on_selector_all(
            "#candidates tbody tr", "rs => rs.map(r => [...r.cells].map(c => c.textContent))")
        assert len(rows) == len(answer["alternatives"])
        for k, (row, alt) in enumerate(zip(rows, answer["alternatives"], strict=True)):
            shown = [float(x) for x in row[2].strip("[]").split(",")]
            assert row[0] == str(k) and row[1] == alt["zone"]
            assert max(abs(a - b) for a, b in zip(shown, alt["world_from_camera"]["translation_m"],
                                                   strict=True)) < 0.006
            assert abs(float(row[3]) - alt["confidence"]) < 6e-4
        assert sorted(r[1] for r in rows) == ["room-a", "room-b"]
        assert page.get_attribute("#view3d", "data-candidates") == "2"
        assert page.get_attribute("#view3d", "data-camera") == "false"
        assert violet_before == 0 and _violet(page) > 50
        # a localized answer (the hint settles it): no candidates left behind
        _localize(page, {**EXAMPLE_REQUEST, "hint": {"zone_id": "room-b"}}, "done")
        assert "in zone room-b" in page.inner_text("#status")
        assert not page.is_visible("#candidates")
        assert page.get_attribute("#view3d", "data-candidates") == "0"
        assert _violet(page) == 0
        op.assert_offline_clean()
        page.close()
    finally:
        httpx.delete(f"{live_server}/v1/maps/{doc['map_id']}")


def _violet(page: object) -> int:
    """Pixels of the 3D canvas painted in the candidates' violet (#d2a8ff, within 40 per
    channel, opaque)."""
    return page.evaluate("""() => {
        const c = document.getElementById('view3d');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4)
            if (d[i + 3] > 200 && Math.abs(d[i] - 210) < 40 && Math.abs(d[i + 1] - 168) < 40
                && Math.abs(d[i + 2] - 255) < 40) n++;
        return n; }""")  # type: ignore[attr-defined, no-any-return]
