"""Draw a localization as SVG: the frame's detections against the map's ellipsoids projected at
the returned pose, inliers vs outliers, and each match's IoU and cost. Pure Python (no numpy,
no gtsam), so an app can draw what the server answered with only the SDK installed.

Inputs are the request sent, the response received and the map document (``GET
/v1/maps/{id}?version=<response.map_version>``, i.e. :meth:`QuadLocClient.get_map` ``.map``)::

    record = client.get_map("chess", version=answer.map_version)
    svg = overlay_svg(request, answer, record.map)      # str, an <svg> document
    Path("frame.svg").write_text(svg)

Conventions (the server's): pixels with the origin at the top-left pixel corner, +x right,
+y down; ellipses ``(cx, cy, a, b, angle)`` with SEMI-axes (px) and ``angle`` in radians from +x
towards +y; ``world_from_camera`` (metres) maps camera to world coordinates; the projection
``C* = P Q* P^T`` uses OpenCV camera axes (+X right, +Y down, +Z forward), so a pose returned in
``opengl`` axes is flipped back with ``diag(1, -1, -1)`` first.

The server's ``POST /v1/maps/{id}/localize`` with ``Accept: image/svg+xml`` draws with
:func:`render_overlay_svg` too, from its own projections (``quadloc.factors.camera``); the two
projections are compared in ``tests/service/api/test_overlay.py``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import escape, quoteattr

__all__ = [
    "DrawnDetection",
    "DrawnProjection",
    "ImageEllipse",
    "detection_ellipse",
    "drawn_detections",
    "overlay_summary",
    "overlay_svg",
    "place_labels",
    "project_ellipsoid",
    "render_overlay_svg",
    "rotation_from_quaternion_wxyz",
    "xml_attribute",
    "xml_text",
]

Matrix = Sequence[Sequence[float]]

#: Smallest camera-frame depth (m) of an ellipsoid for its projection to count as an ellipse
#: (the server's ``quadloc.factors.camera.MIN_DEPTH``).
MIN_DEPTH_M = 1e-6


@dataclass(frozen=True)
class ImageEllipse:
    """Image ellipse: centre ``(cx, cy)`` px, semi-axes ``a >= b`` px, ``angle`` radians from +x
    towards +y (direction of ``a``)."""

    cx: float
    cy: float
    a: float
    b: float
    angle: float


@dataclass(frozen=True)
class DrawnDetection:
    """A detection to draw: its ellipse, label, and (for an inlier) the matched object, IoU and
    metric cost."""

    index: int
    label: str
    ellipse: ImageEllipse
    object_id: str | None = None
    iou: float | None = None
    cost: float | None = None


@dataclass(frozen=True)
class DrawnProjection:
    """A map object projected at the returned pose (``ellipse`` None: not an ellipse there,
    e.g. behind the camera; it is then not drawn)."""

    object_id: str
    category: str
    ellipse: ImageEllipse | None


# ------------------------------------------------------------------------------ small algebra


def _matmul(a: Matrix, b: Matrix) -> list[list[float]]:
    return [[sum(a[i][k] * b[k][j] for k in range(len(b))) for j in range(len(b[0]))]
            for i in range(len(a))]


def _transpose(a: Matrix) -> list[list[float]]:
    return [list(col) for col in zip(*a, strict=True)]


def rotation_from_quaternion_wxyz(q: Sequence[float]) -> list[list[float]]:
    """3x3 rotation (list of rows) of a quaternion ``(w, x, y, z)`` (normalised here)."""
    if len(q) != 4:
        raise ValueError(f"quaternion_wxyz: expected 4 numbers, got {len(q)}")
    n = math.sqrt(sum(v * v for v in q))
    if not n > 0 or not math.isfinite(n):
        raise ValueError("quaternion_wxyz: must be finite and non-zero")
    w, x, y, z = (v / n for v in q)
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def _camera_from_world(world_from_camera: Matrix) -> tuple[list[list[float]], list[float]]:
    """``(R_cw, t_cw)`` of the inverse of a rigid 4x4 ``world_from_camera``."""
    R = [list(row[:3]) for row in world_from_camera[:3]]
    t = [row[3] for row in world_from_camera[:3]]
    Rt = _transpose(R)
    return Rt, [-sum(Rt[i][k] * t[k] for k in range(3)) for i in range(3)]


def _ellipse_from_dual_conic(C: Matrix) -> ImageEllipse | None:
    """Centre, semi-axes and angle of the ellipse of a dual conic (any scale); None when it is
    not a real ellipse. ``Cn = C* / (-C*[2,2])``, ``c = -Cn[:2,2]``,
    ``A^-1 = Cn[:2,:2] + c c^T``."""
    s = -C[2][2]
    if s == 0 or not math.isfinite(s):
        return None
    # Cn = C / s, so c = -Cn[:2, 2] = -C[:2, 2] / s and A^-1 = C[:2, :2] / s + c c^T
    cx, cy = -(C[0][2] / s), -(C[1][2] / s)
    sxx = C[0][0] / s + cx * cx
    syy = C[1][1] / s + cy * cy
    sxy = C[0][1] / s + cx * cy
    # eigenvalues of the symmetric [[sxx, sxy], [sxy, syy]] (= a^2, b^2)
    mean, diff = (sxx + syy) / 2, math.hypot((sxx - syy) / 2, sxy)
    l1, l2 = mean + diff, mean - diff
    if not (l2 > 0 and math.isfinite(l1)):
        return None
    angle = 0.5 * math.atan2(2 * sxy, sxx - syy)
    return ImageEllipse(cx, cy, math.sqrt(l1), math.sqrt(l2), angle)


def project_ellipsoid(
    center: Sequence[float],
    axes: Sequence[float],
    quaternion_wxyz: Sequence[float],
    world_from_camera: Matrix,
    fx: float, fy: float, cx: float, cy: float,
) -> ImageEllipse | None:
    """Image ellipse of an ellipsoid (``center`` world m, semi-``axes`` m, orientation
    ellipsoid->world as ``quaternion_wxyz``) seen from the 4x4 ``world_from_camera`` (OpenCV
    camera axes) with pinhole intrinsics (px). ``C* = P Q* P^T`` with ``P = K [R_cw | t_cw]``
    and ``Q* = T diag(a^2, b^2, c^2, -1) T^T``. None when the ellipsoid is not entirely in
    front of the camera (its smallest depth ``z_c - sqrt(r3^T M r3)`` is <= ``MIN_DEPTH_M``):
    the projection is then not an ellipse."""
    R_e = rotation_from_quaternion_wxyz(quaternion_wxyz)
    R_cw, t_cw = _camera_from_world(world_from_camera)
    # shape matrix M = R_e diag(axes^2) R_e^T, depth check along the optical axis r3
    M = _matmul(_matmul(R_e, [[axes[0] ** 2, 0, 0], [0, axes[1] ** 2, 0], [0, 0, axes[2] ** 2]]),
                _transpose(R_e))
    r3 = R_cw[2]
    zc = sum(r3[k] * center[k] for k in range(3)) + t_cw[2]
    extent = math.sqrt(max(sum(r3[i] * M[i][j] * r3[j] for i in range(3) for j in range(3)),
                           0.0))
    if not zc - extent > MIN_DEPTH_M:
        return None
    T = [R_e[0] + [center[0]], R_e[1] + [center[1]], R_e[2] + [center[2]], [0.0, 0.0, 0.0, 1.0]]
    D = [[axes[0] ** 2, 0.0, 0.0, 0.0], [0.0, axes[1] ** 2, 0.0, 0.0],
         [0.0, 0.0, axes[2] ** 2, 0.0], [0.0, 0.0, 0.0, -1.0]]
    Q = _matmul(_matmul(T, D), _transpose(T))
    K = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    P = _matmul(K, [R_cw[i] + [t_cw[i]] for i in range(3)])
    return _ellipse_from_dual_conic(_matmul(_matmul(P, Q), _transpose(P)))


# ------------------------------------------------------------------------------ drawing

_STYLE = """
.frame{fill:#1b1f24;stroke:#8a949e;stroke-width:1}
.projection{fill:none;stroke:#58a6ff;stroke-width:1.5;stroke-dasharray:6 4}
.projection.matched{stroke-dasharray:none;stroke-width:2}
.detection{fill:none;stroke-width:2.5}
.detection.inlier{stroke:#3fb950}
.detection.outlier{stroke:#f85149;stroke-dasharray:3 3}
.match{stroke:#d29922;stroke-width:1.5}
text{font-family:sans-serif;font-size:11px;fill:#e6edf3;paint-order:stroke;stroke:#0d1117;
stroke-width:3px}
text.pid{fill:#79c0ff}
text.summary{font-size:14px}
"""


#: Characters XML 1.0 does not allow in a document (C0 controls but tab, LF, CR; lone
#: surrogates; U+FFFE, U+FFFF): an SVG holding one is not well-formed, so text drawn from a
#: request or a map has each replaced by U+FFFD.
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    """``text`` escaped as XML character data, every character XML 1.0 forbids replaced by
    U+FFFD (the SVG stays well-formed whatever the labels hold)."""
    return escape(_NOT_XML.sub("\ufffd", text))


def xml_attribute(text: str) -> str:
    """``text`` as a quoted XML attribute value, forbidden characters replaced as in
    :func:`xml_text`."""
    return quoteattr(_NOT_XML.sub("\ufffd", text))


def _ellipse_svg(e: ImageEllipse, cls: str, extra: str = "") -> str:
    deg = math.degrees(e.angle)
    return (f'<ellipse class="{cls}" cx="{e.cx:.2f}" cy="{e.cy:.2f}" rx="{e.a:.2f}" '
            f'ry="{e.b:.2f}" transform="rotate({deg:.3f} {e.cx:.2f} {e.cy:.2f})"{extra}/>')


#: Label text metrics (the style's 11 px font): each label is drawn exactly
#: ``LABEL_CHAR_PX`` px per character wide (``textLength``: the same box in every browser and
#: font), its box spans ``LABEL_ASCENT_PX`` above the baseline to ``LABEL_DESCENT_PX`` below.
LABEL_CHAR_PX = 6.2
LABEL_ASCENT_PX = 11.0
LABEL_DESCENT_PX = 3.0
#: Free space kept between two labels and between a label and the frame's edge (px).
LABEL_GAP_PX = 2.0


def place_labels(labels: Sequence[tuple[str, ImageEllipse]], width: int, height: int
                 ) -> list[tuple[float, float, float]]:
    """Where to write each ``(text, ellipse)`` label: ``(x centre, baseline y, width)`` px.

    Greedy, in the given order (the first get the best places): a label goes under its
    ellipse, else above it, else ever further from it in steps of one line, at the first place
    whose box is inside the ``width`` x ``height`` frame and overlaps no label placed before
    (boxes ``LABEL_GAP_PX`` apart); its x is moved inwards so the box never crosses the left or
    right edge. When no free place exists within the frame the label goes under its ellipse
    (clamped into the frame)."""
    line = LABEL_ASCENT_PX + LABEL_DESCENT_PX + LABEL_GAP_PX
    y_min = LABEL_ASCENT_PX + LABEL_GAP_PX
    y_max = height - LABEL_DESCENT_PX - LABEL_GAP_PX
    boxes: list[tuple[float, float, float, float]] = []
    out: list[tuple[float, float, float]] = []
    for text, e in labels:
        w = max(len(text), 1) * LABEL_CHAR_PX
        half = min(w / 2, width / 2 - LABEL_GAP_PX)
        x = min(max(e.cx, half + LABEL_GAP_PX), width - half - LABEL_GAP_PX)
        # vertical half-extent of the ellipse: sqrt(a^2 sin^2 + b^2 cos^2)
        extent = math.hypot(e.a * math.sin(e.angle), e.b * math.cos(e.angle))
        below = e.cy + extent + LABEL_ASCENT_PX + LABEL_GAP_PX
        above = e.cy - extent - LABEL_DESCENT_PX - LABEL_GAP_PX
        candidates = [below, above]
        for k in range(1, int(height / line) + 2):
            candidates += [below + k * line, above - k * line]
        chosen = None
        for y in candidates:
            if not y_min <= y <= y_max:
                continue
            box = (x - half - LABEL_GAP_PX, y - LABEL_ASCENT_PX - LABEL_GAP_PX,
                   x + half + LABEL_GAP_PX, y + LABEL_DESCENT_PX + LABEL_GAP_PX)
            if all(box[2] <= b[0] or b[2] <= box[0] or box[3] <= b[1] or b[3] <= box[1]
                   for b in boxes):
                chosen = box, y
                break
        if chosen is None:
            y = min(max(below, y_min), max(y_min, y_max))
            chosen = (x - half, y - LABEL_ASCENT_PX, x + half, y + LABEL_DESCENT_PX), y
        boxes.append(chosen[0])
        out.append((x, chosen[1], 2 * half))
    return out


def render_overlay_svg(
    width: int,
    height: int,
    detections: Sequence[DrawnDetection],
    projections: Sequence[DrawnProjection],
    summary: str,
    *,
    metadata: Mapping[str, Any] | None = None,
) -> str:
    """An SVG document of a ``width`` x ``height`` px image frame with the map's projected
    ellipses (blue; solid when matched, dashed otherwise), the detections (green inliers, red
    dashed outliers), a line from each inlier to its object's projection with ``IoU``/``cost``,
    and ``summary`` in a band under the frame. ``metadata`` (e.g. the JSON response) is embedded
    as ``<metadata id="quadloc-result">`` JSON text. Elements carry ``class`` and ``data-*``
    attributes (``data-detection-index``, ``data-object-id``) so tools can read them back."""
    band = 28
    matched = {d.object_id for d in detections if d.object_id is not None}
    by_id = {p.object_id: p for p in projections}
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height + band}" '
           f'viewBox="0 0 {width} {height + band}" class="quadloc-overlay">',
           f"<style>{_STYLE}</style>"]
    if metadata is not None:
        # (json.dumps escapes every non-ASCII character: the text is ASCII)
        out.append(f'<metadata id="quadloc-result">{xml_text(json.dumps(metadata))}'
                   "</metadata>")
    out.append(f'<rect class="frame" x="0" y="0" width="{width}" height="{height}"/>')
    out.append(f'<clipPath id="image"><rect x="0" y="0" width="{width}" height="{height}"/>'
               "</clipPath><g clip-path=\"url(#image)\">")
    labels: list[tuple[str, str, ImageEllipse]] = []  # (class, text, ellipse), in priority
    for p in projections:
        e = p.ellipse
        # not an ellipse at that pose, or wholly outside the frame (its circumscribed circle,
        # radius a, misses the image): not drawn, so a large map gives a small drawing
        if e is None or (e.cx + e.a < 0 or e.cy + e.a < 0 or e.cx - e.a > width
                          or e.cy - e.a > height):
            continue
        cls = "projection matched" if p.object_id in matched else "projection"
        out.append(_ellipse_svg(e, cls, f" data-object-id={xml_attribute(p.object_id)}"))
        if p.object_id not in matched:  # a matched object is named by its detection's label
            labels.append(("pid", f"{p.object_id} {p.category}", e))
    detection_labels: list[tuple[str, str, ImageEllipse]] = []
    for d in detections:
        inlier = d.object_id is not None
        cls = "detection inlier" if inlier else "detection outlier"
        out.append(_ellipse_svg(d.ellipse, cls, f' data-detection-index="{d.index}"'))
        label = f"#{d.index} {d.label}"
        proj = by_id.get(d.object_id) if d.object_id is not None else None
        if proj is not None and proj.ellipse is not None:
            out.append(f'<line class="match" x1="{d.ellipse.cx:.2f}" y1="{d.ellipse.cy:.2f}" '
                       f'x2="{proj.ellipse.cx:.2f}" y2="{proj.ellipse.cy:.2f}"/>')
        if inlier:
            label += f" -> {d.object_id}  IoU {d.iou:.2f}  cost {d.cost:.3g}"
        else:
            label += "  (outlier)"
        detection_labels.append(("label", label, d.ellipse))
    # labels on top of every drawing, detections' first (they get the best places)
    placed = place_labels([(text, e) for _, text, e in detection_labels + labels], width,
                          height)
    for (cls, text, _), (x, y, w) in zip(detection_labels + labels, placed, strict=True):
        out.append(f'<text class="{cls}" x="{x:.1f}" y="{y:.1f}" text-anchor="middle" '
                   f'textLength="{w:.1f}" lengthAdjust="spacingAndGlyphs">{xml_text(text)}</text>')
    out.append("</g>")
    out.append(f'<text class="summary" x="6" y="{height + band - 9}">{xml_text(summary)}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------ from wire data


def _plain(obj: Any) -> Any:
    """A pydantic model (SDK or server) -> its JSON-like dict; dicts pass through."""
    dump = getattr(obj, "model_dump", None)
    return dump(mode="json") if callable(dump) else obj


def detection_ellipse(detection: Mapping[str, Any]) -> ImageEllipse:
    """The ellipse of a wire detection; a box ``{xmin, ymin, xmax, ymax}`` becomes its inscribed
    axis-aligned ellipse (as the server does)."""
    e = detection.get("ellipse")
    if e is not None:
        return ImageEllipse(e["cx"], e["cy"], e["a"], e["b"], e.get("angle", 0.0))
    b = detection["box"]
    return ImageEllipse((b["xmin"] + b["xmax"]) / 2, (b["ymin"] + b["ymax"]) / 2,
                        (b["xmax"] - b["xmin"]) / 2, (b["ymax"] - b["ymin"]) / 2, 0.0)


def overlay_summary(response: Mapping[str, Any], n_detections: int) -> str:
    """One line: localized or not (reason), confidence, inliers/detections, metric, map."""
    where = f"map {response.get('map_id')} v{response.get('map_version')}"
    if not response.get("localized"):
        return f"NOT localized ({response.get('reason')}) - {where}"
    return (f"localized  confidence {response.get('confidence', 0.0):.2f}  inliers "
            f"{len(response.get('inliers', []))}/{n_detections}  metric {response.get('metric')}"
            f"  {where}")


def drawn_detections(request: Mapping[str, Any],
                     response: Mapping[str, Any]) -> list[DrawnDetection]:
    """The request's detections, each marked with its inlier match (if any) from ``response``."""
    matches = {m["detection_index"]: m for m in response.get("inliers", [])}
    out = []
    for i, det in enumerate(request["detections"]):
        m = matches.get(i)
        out.append(DrawnDetection(i, det["label"], detection_ellipse(det),
                                  None if m is None else m["object_id"],
                                  None if m is None else m["iou"],
                                  None if m is None else m["cost"]))
    return out


def _opencv_world_from_camera(pose: Mapping[str, Any]) -> list[list[float]]:
    T = [list(map(float, row)) for row in pose["matrix"]]
    if pose.get("convention", "opencv") == "opengl":  # T_cv = T_gl diag(1, -1, -1, 1)
        for row in T[:3]:
            row[1], row[2] = -row[1], -row[2]
    return T


def overlay_svg(request: Any, response: Any, scene_map: Any) -> str:
    """SVG overlay of a localization (see the module docstring), computed client-side.

    ``request``: the :class:`~quadloc_sdk.models.LocalizeRequest` (or its JSON dict) that was sent;
    ``response``: the :class:`~quadloc_sdk.models.LocalizeResponse` (or dict) received;
    ``scene_map``: the map document of ``response.map_version`` (``MapRecord.map`` or the dict of
    docs/maps.md, objects with ``quaternion_wxyz`` or ``rotation``). Not localized: only the
    detections (all outliers) are drawn."""
    req, resp, doc = _plain(request), _plain(response), _plain(scene_map)
    if isinstance(doc, Mapping) and "map" in doc and "objects" not in doc:
        doc = doc["map"]  # a MapRecord dict
    cam = req["camera"]
    projections: list[DrawnProjection] = []
    pose = resp.get("world_from_camera")
    if resp.get("localized") and pose is not None:
        T = _opencv_world_from_camera(pose)
        for obj in doc["objects"]:
            q = obj.get("quaternion_wxyz")
            if q is None and obj.get("rotation") is not None:
                q = _quaternion_wxyz_from_rotation(obj["rotation"])
            ellipse = project_ellipsoid(obj["center"], obj["axes"], q or [1.0, 0.0, 0.0, 0.0],
                                        T, cam["fx"], cam["fy"], cam["cx"], cam["cy"])
            projections.append(DrawnProjection(str(obj["object_id"]), str(obj["category"]),
                                               ellipse))
    dets = drawn_detections(req, resp)
    return render_overlay_svg(int(cam["width"]), int(cam["height"]), dets, projections,
                              overlay_summary(resp, len(dets)))


def _quaternion_wxyz_from_rotation(R: Matrix) -> list[float]:
    """Unit quaternion (w, x, y, z) of a 3x3 rotation (Shepperd's method, w >= 0)."""
    tr = R[0][0] + R[1][1] + R[2][2]
    if tr > 0:
        s = 2 * math.sqrt(tr + 1)
        q = [s / 4, (R[2][1] - R[1][2]) / s, (R[0][2] - R[2][0]) / s, (R[1][0] - R[0][1]) / s]
    elif R[0][0] > R[1][1] and R[0][0] > R[2][2]:
        s = 2 * math.sqrt(1 + R[0][0] - R[1][1] - R[2][2])
        q = [(R[2][1] - R[1][2]) / s, s / 4, (R[0][1] + R[1][0]) / s, (R[0][2] + R[2][0]) / s]
    elif R[1][1] > R[2][2]:
        s = 2 * math.sqrt(1 + R[1][1] - R[0][0] - R[2][2])
        q = [(R[0][2] - R[2][0]) / s, (R[0][1] + R[1][0]) / s, s / 4, (R[1][2] + R[2][1]) / s]
    else:
        s = 2 * math.sqrt(1 + R[2][2] - R[0][0] - R[1][1])
        q = [(R[1][0] - R[0][1]) / s, (R[0][2] + R[2][0]) / s, (R[1][2] + R[2][1]) / s, s / 4]
    return [-v for v in q] if q[0] < 0 else q
