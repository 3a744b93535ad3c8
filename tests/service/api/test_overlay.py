"""The localization overlay: the SDK's pure-Python projection against the solver's
(quadloc.factors.camera), the SVG drawn by the server (Accept: image/svg+xml) and by the SDK from
the same answer, and content negotiation."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.camera import project_ellipsoid as solver_projection
from quadloc.factors.conics import DegenerateProjectionError
from quadloc.factors.rotations import invert_pose
from quadloc.maps.demo import load_demo_map
from quadloc.service.api.inspector import wants_svg
from quadloc.service.schemas.examples import EXAMPLE_TRUE_WORLD_FROM_CAMERA, LOCALIZE_EXAMPLE
from quadloc_sdk.overlay import overlay_svg, project_ellipsoid
from tests.conftest import make_test_app
from tests.support.helpers import angle_diff, surface_points


def test_sdk_projection_matches_the_solver_on_the_chess_map() -> None:
    scene = load_demo_map().to_dict()
    c = LOCALIZE_EXAMPLE["camera"]
    camera = Camera(c["fx"], c["fy"], c["cx"], c["cy"], c["width"], c["height"])
    rng = np.random.default_rng(3)
    compared = degenerate = 0
    for k in range(6):
        T = np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)
        if k:  # other viewpoints: rotate about the world up axis, move around
            a = math.pi if k == 5 else rng.uniform(-0.6, 0.6)  # k = 5: facing away
            Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0],
                           [0, 0, 1]])
            T[:3, :3] = Rz @ T[:3, :3]
            T[:3, 3] += rng.normal(0, 0.3, 3)
        for obj in scene["objects"]:
            e = Ellipsoid.from_quaternion_wxyz(obj["center"], obj["axes"], obj["quaternion_wxyz"])
            mine = project_ellipsoid(obj["center"], obj["axes"], obj["quaternion_wxyz"],
                                     T.tolist(), c["fx"], c["fy"], c["cx"], c["cy"])
            try:
                ref = solver_projection(camera, invert_pose(T), e).canonical()
            except DegenerateProjectionError:
                assert mine is None
                degenerate += 1
                continue
            assert mine is not None
            np.testing.assert_allclose([mine.cx, mine.cy, mine.a, mine.b],
                                       [ref.cx, ref.cy, ref.a, ref.b], rtol=1e-7, atol=1e-6)
            if ref.a - ref.b > 1e-6 * ref.a:  # angle undefined for a circle
                assert angle_diff(mine.angle, ref.angle) < 1e-7
            compared += 1
    assert compared > 30 and degenerate > 0, (compared, degenerate)


def test_projection_touches_the_projected_surface_points() -> None:
    """Independent check: surface points of the ellipsoid project inside the ellipse (level
    <= 1) and the outermost ones on it (max level = 1)."""
    center, axes, q = [0.2, -0.1, 3.0], [0.4, 0.2, 0.3], [0.9, 0.1, -0.3, 0.2]
    q = list(np.array(q) / np.linalg.norm(q))
    T = np.eye(4)
    e = project_ellipsoid(center, axes, q, T.tolist(), 500.0, 480.0, 320.0, 240.0)
    assert e is not None
    pts = surface_points(Ellipsoid.from_quaternion_wxyz(center, axes, q), 64, 32)
    uv = np.c_[500.0 * pts[:, 0] / pts[:, 2] + 320.0, 480.0 * pts[:, 1] / pts[:, 2] + 240.0]
    R = np.array([[math.cos(e.angle), -math.sin(e.angle)], [math.sin(e.angle), math.cos(e.angle)]])
    local = (uv - [e.cx, e.cy]) @ R
    level = (local[:, 0] / e.a) ** 2 + (local[:, 1] / e.b) ** 2
    assert level.max() == pytest.approx(1.0, abs=2e-3)


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    with TestClient(make_test_app(tmp_path_factory.mktemp("overlay"))) as c:
        yield c


def _count(svg: str, cls: str) -> int:
    return len(re.findall(rf'<ellipse class="{cls}"', svg))


def test_server_svg_and_sdk_overlay_draw_the_same_frame(client: TestClient) -> None:
    r = client.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE,
                    headers={"Accept": "image/svg+xml"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("image/svg+xml")
    svg = r.text
    meta = re.search(r'<metadata id="quadloc-result">(.*?)</metadata>', svg, re.S)
    assert meta is not None
    import html

    answer = json.loads(html.unescape(meta.group(1)))
    n = len(LOCALIZE_EXAMPLE["detections"])
    assert answer["localized"] is True
    assert _count(svg, "detection inlier") == len(answer["inliers"])
    assert _count(svg, "detection inlier") + _count(svg, "detection outlier") == n
    assert _count(svg, "projection matched") == len({m["object_id"] for m in answer["inliers"]})
    # the SDK draws the same frame from the JSON answer and the map document
    record = client.get(f"/v1/maps/chess?version={answer['map_version']}").json()
    client_svg = overlay_svg(LOCALIZE_EXAMPLE, answer, record["map"])
    strip = re.compile(r"<metadata.*?</metadata>\n", re.S)
    assert strip.sub("", svg) == client_svg
    # and the JSON body of the same request is the embedded answer (timings aside)
    plain = client.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE).json()
    for key in ("localized", "world_from_camera", "inliers", "confidence", "map_version"):
        assert plain[key] == answer[key], key


def test_opengl_answer_draws_identically(client: TestClient) -> None:
    gl = json.loads(json.dumps(LOCALIZE_EXAMPLE))
    gl["options"] = {**gl.get("options", {}), "output_convention": "opengl"}
    cv = client.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE).json()
    answer = client.post("/v1/maps/chess/localize", json=gl).json()
    doc = client.get("/v1/maps/chess").json()["map"]
    assert overlay_svg(gl, answer, doc) == overlay_svg(LOCALIZE_EXAMPLE, cv, doc)


def test_not_localized_draws_outliers_only(client: TestClient) -> None:
    frame = {**LOCALIZE_EXAMPLE, "detections": LOCALIZE_EXAMPLE["detections"][:1]}
    r = client.post("/v1/maps/chess/localize", json=frame, headers={"Accept": "image/svg+xml"})
    assert r.status_code == 200
    assert "NOT localized" in r.text
    assert _count(r.text, "detection outlier") == 1 and "projection" not in r.text.split(
        "</style>")[1]


def test_errors_stay_problem_json_with_svg_accept(client: TestClient) -> None:
    bad = {**LOCALIZE_EXAMPLE, "camera": {**LOCALIZE_EXAMPLE["camera"], "fx": -1}}
    r = client.post("/v1/maps/chess/localize", json=bad, headers={"Accept": "image/svg+xml"})
    assert r.status_code == 422
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "camera.fx" in r.text


@pytest.mark.parametrize(("accept", "svg"), [
    (None, False), ("application/json", False), ("*/*", False),
    ("image/svg+xml", True), ("image/svg+xml, application/json;q=0.5", True),
    ("application/json, image/svg+xml;q=0.9", False), ("image/svg+xml;q=0", False),
    ("text/html, image/svg+xml", True),
])
def test_accept_negotiation(accept: str | None, svg: bool) -> None:
    assert wants_svg(accept) is svg


def test_inspector_page_and_assets_are_served(client: TestClient) -> None:
    page = client.get("/inspector")
    assert page.status_code == 200 and "inspector.js" in page.text
    assert "default-src 'self'" in page.headers["content-security-policy"]
    for name in ("inspector.js", "inspector.css"):
        assert client.get(f"/static/inspector/{name}").status_code == 200
    assert client.get("/inspector/example.json").json() == LOCALIZE_EXAMPLE
    # nothing the page, its script or its style loads comes from another host
    static = Path(__file__).resolve().parents[3] / "service" / "api" / "static" / "inspector"
    for f in static.iterdir():
        assert not re.search(r"https?://", f.read_text()), f


def test_offline_docs_pages_point_at_local_assets(client: TestClient) -> None:
    for path, asset in (("/docs", "swagger-ui-bundle.js"), ("/redoc", "redoc.standalone.js")):
        page = client.get(path)
        assert page.status_code == 200
        assert f"/static/docs/{asset}" in page.text
        assert not re.search(r"(src|href)=\"https?://", page.text), page.text
        assert client.get(f"/static/docs/{asset}").status_code == 200
        assert "default-src 'self'" in page.headers["content-security-policy"]


def test_drawing_escapes_text_and_skips_what_is_off_frame() -> None:
    from quadloc_sdk.overlay import (
        DrawnDetection,
        DrawnProjection,
        ImageEllipse,
        render_overlay_svg,
    )

    inside = DrawnProjection("in", "chair", ImageEllipse(100, 100, 20, 10, 0.3))
    outside = DrawnProjection("out", "chair", ImageEllipse(900, 100, 20, 10, 0.0))
    behind = DrawnProjection("behind", "chair", None)
    det = DrawnDetection(0, "<script>alert(1)</script>", ImageEllipse(100, 100, 20, 10, 0.3),
                         "in", 0.9, 0.01)
    svg = render_overlay_svg(640, 480, [det], [inside, outside, behind], 'a "summary" & <b>',
                             metadata={"x": "</metadata><script>"})
    assert 'data-object-id="in"' in svg
    assert 'data-object-id="out"' not in svg and 'data-object-id="behind"' not in svg
    assert "<script>" not in svg and "&lt;script&gt;" in svg
    import xml.etree.ElementTree as ET

    ET.fromstring(svg)  # well-formed XML


def test_labels_are_placed_inside_the_frame_and_apart() -> None:
    """``place_labels`` on crowded frames (random ellipses, some at the edges): every label box
    (``LABEL_CHAR_PX`` per character wide, ascent/descent around the baseline) lies inside the
    frame and overlaps no other; a lone label sits centred under its ellipse."""
    import numpy as np

    from quadloc_sdk.overlay import (
        LABEL_ASCENT_PX,
        LABEL_CHAR_PX,
        LABEL_DESCENT_PX,
        ImageEllipse,
        place_labels,
    )

    width, height = 640, 480
    rng = np.random.default_rng(3)
    for n in (5, 12, 20):
        labels = [(f"#{i} Chair -> {i}  IoU 0.{i:02d}  cost 0.0{i}" if i % 2 else f"o{i} Box",
                   ImageEllipse(float(rng.uniform(-20, width + 20)),
                                float(rng.uniform(0, height)), float(rng.uniform(3, 60)),
                                float(rng.uniform(3, 40)), float(rng.uniform(-1.5, 1.5))))
                  for i in range(n)]
        placed = place_labels(labels, width, height)
        boxes = []
        for (text, _), (x, y, w) in zip(labels, placed, strict=True):
            assert w == pytest.approx(min(len(text) * LABEL_CHAR_PX, width - 4))
            box = (x - w / 2, y - LABEL_ASCENT_PX, x + w / 2, y + LABEL_DESCENT_PX)
            assert box[0] >= 0 and box[2] <= width and box[1] >= 0 and box[3] <= height, box
            boxes.append(box)
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (a, b)
    e = ImageEllipse(300.0, 200.0, 40.0, 20.0, 0.0)
    [(x, y, _)] = place_labels([("#0 TV", e)], width, height)
    assert x == 300.0 and y > 200.0 + 20.0
