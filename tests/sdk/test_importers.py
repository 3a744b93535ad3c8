"""quadloc_sdk.importers against independent computations: poses from axis-angle (Rodrigues,
written here) and hand-made files, COLMAP's camera_from_world inverted (camera centre
``-R^T t``), COCO RLE masks decoded (by hand for the compressed form, and against an encoder
written here from COCO's definition), moments of known shapes in closed form, and the
written recording accepted by the server's wire model and conversion."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bench.import_example import encode_rle_counts, rle_counts
from quadloc.service.app.builds import recording_of
from quadloc_sdk import importers
from quadloc_sdk.geometry import polygon_moments


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    n = axis / np.linalg.norm(axis)
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _quat_wxyz(axis: np.ndarray, angle: float) -> list[float]:
    n = axis / np.linalg.norm(axis)
    return [math.cos(angle / 2), *(math.sin(angle / 2) * n)]


AXES = [(np.array([0.3, -1.0, 0.4]), 0.7), (np.array([1.0, 0.2, 0.0]), -2.1)]
TRANSLATIONS = [np.array([0.5, -0.2, 1.5]), np.array([-1.0, 0.3, 0.25])]


def test_tum_trajectory_is_world_from_camera_with_scalar_last_quaternions() -> None:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for k, ((axis, ang), t) in enumerate(zip(AXES, TRANSLATIONS, strict=True)):
        w, x, y, z = _quat_wxyz(axis, ang)
        lines.append(f"{1305031102.1 + k:.4f} {t[0]} {t[1]} {t[2]} {x} {y} {z} {w}")
    poses = importers.read_tum_trajectory("\n".join(lines) + "\n")
    assert list(poses) == ["1305031102.1000", "1305031103.1000"]
    for T, (axis, ang), t in zip(poses.values(), AXES, TRANSLATIONS, strict=True):
        np.testing.assert_allclose(T[:3, :3], _rodrigues(axis, ang), atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], t, atol=1e-12)
        np.testing.assert_allclose(T[3], [0, 0, 0, 1])
    named = importers.match_timestamps(
        poses, "1305031102.105 rgb/a.png\n1305031103.099 rgb/b.png\n1305031104.5 rgb/c.png\n")
    assert list(named) == ["rgb/a.png", "rgb/b.png"]  # c: no pose within 20 ms
    with pytest.raises(ValueError, match="line 1"):
        importers.read_tum_trajectory("1.0 0 0 0 0 0 0\n")
    with pytest.raises(ValueError, match="quaternion norm"):
        importers.read_tum_trajectory("1.0 0 0 0 0 0 0 2\n")


COLMAP_IMAGES = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 2, mean observations per image: 1
1 {q0} {t0} 1 frame 000.jpg
100.5 200.5 -1
2 {q1} {t1} 1 frame 001.jpg

"""


def test_colmap_images_are_inverted_from_camera_from_world() -> None:
    text = COLMAP_IMAGES.format(
        q0=" ".join(map(str, _quat_wxyz(*AXES[0]))), t0=" ".join(map(str, TRANSLATIONS[0])),
        q1=" ".join(map(str, _quat_wxyz(*AXES[1]))), t1=" ".join(map(str, TRANSLATIONS[1])))
    poses = importers.read_colmap_images(text)
    assert list(poses) == ["frame 000.jpg", "frame 001.jpg"]  # names may hold spaces
    for T, (axis, ang), t in zip(poses.values(), AXES, TRANSLATIONS, strict=True):
        R = _rodrigues(axis, ang)  # camera_from_world rotation
        np.testing.assert_allclose(T[:3, :3], R.T, atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], -R.T @ t, atol=1e-12)  # the camera centre
        # a world point maps back: camera_from_world(world_from_camera(p)) = p
        p = np.array([0.1, 0.2, 3.0])
        np.testing.assert_allclose(R @ (T[:3, :3] @ p + T[:3, 3]) + t, p, atol=1e-12)


def test_colmap_cameras_pinhole_only() -> None:
    text = ("# Camera list\n1 PINHOLE 640 480 525.0 526.0 319.5 239.5\n"
            "2 SIMPLE_PINHOLE 320 240 300 160 120\n3 OPENCV 640 480 1 1 1 1 0.1 0 0 0\n")
    assert importers.read_colmap_camera(text) == {"fx": 525.0, "fy": 526.0, "cx": 319.5,
                                                  "cy": 239.5, "width": 640, "height": 480}
    assert importers.read_colmap_camera(text, 2) == {"fx": 300.0, "fy": 300.0, "cx": 160.0,
                                                     "cy": 120.0, "width": 320, "height": 240}
    with pytest.raises(ValueError, match="OPENCV"):
        importers.read_colmap_camera(text, 3)


def test_ar_log_columns_and_column_major_are_the_same_pose() -> None:
    T = np.eye(4)
    T[:3, :3] = _rodrigues(*AXES[0])
    T[:3, 3] = TRANSLATIONS[0]
    log = {"frames": [{"name": "a", "transform": T.T.tolist()},  # 4 columns
                      {"timestamp": 12.5, "matrix_column_major": T.T.reshape(16).tolist()}]}
    poses = importers.read_ar_log(log)
    assert list(poses) == ["a", "12.5"]
    for P in poses.values():
        np.testing.assert_allclose(P, T, atol=0)
    with pytest.raises(ValueError, match=r"frames\[0\]"):
        importers.read_ar_log({"frames": [{"transform": [[1, 0, 0]]}]})


# ------------------------------------------------------------------ COCO


def test_rle_decoding_by_hand() -> None:
    # size 2x3, counts [2, 3, 1] column-major: columns (0, 0), (1, 1), (1, 0)
    expected = np.array([[0, 1, 1], [0, 1, 0]], bool)
    for counts in ([2, 3, 1], "231"):
        np.testing.assert_array_equal(
            importers.decode_coco_rle({"size": [2, 3], "counts": counts}), expected)
    # a count below the one two before it is stored negative: "O" is -1, + counts[1] = 1
    assert encode_rle_counts([5, 2, 3, 1]) == "523O"
    m = importers.decode_coco_rle({"size": [1, 11], "counts": "523O"})
    np.testing.assert_array_equal(m[0], [0] * 5 + [1] * 2 + [0] * 3 + [1])
    with pytest.raises(ValueError, match="add up"):
        importers.decode_coco_rle({"size": [2, 3], "counts": [2, 3]})


def _ellipse_mask(h: int, w: int, cx: float, cy: float, a: float, b: float, ang: float
                  ) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w] + 0.5  # pixel centres, top-left corner origin
    dx, dy = x - cx, y - cy
    u = dx * math.cos(ang) + dy * math.sin(ang)
    v = -dx * math.sin(ang) + dy * math.cos(ang)
    return (u / a) ** 2 + (v / b) ** 2 <= 1.0


def _same_ellipse(e: dict[str, float], cx: float, cy: float, a: float, b: float, ang: float,
                  centre_px: float, axis_rel: float, angle_rad: float) -> None:
    assert abs(e["cx"] - cx) <= centre_px and abs(e["cy"] - cy) <= centre_px, e
    assert abs(e["a"] / a - 1) <= axis_rel and abs(e["b"] / b - 1) <= axis_rel, e
    d = (e["angle"] - ang + math.pi / 2) % math.pi - math.pi / 2  # an axis, not a direction
    assert abs(d) <= angle_rad, e


def test_masks_polygons_and_boxes_become_their_ellipses() -> None:
    """A rasterised ellipse (cx 100.3, cy 80.7, a 40, b 20, 0.5 rad) given as an RLE mask
    (list and compressed counts) and as a 720-vertex polygon comes back within 0.05 px, 1 %
    and 0.5 deg (the pixelisation); a box gives its inscribed ellipse exactly."""
    cx, cy, a, b, ang = 100.3, 80.7, 40.0, 20.0, 0.5
    mask = _ellipse_mask(160, 200, cx, cy, a, b, ang)
    counts = rle_counts(mask)
    t = np.linspace(0, 2 * math.pi, 720, endpoint=False)
    poly = np.column_stack([cx + a * np.cos(t) * math.cos(ang) - b * np.sin(t) * math.sin(ang),
                            cy + a * np.cos(t) * math.sin(ang) + b * np.sin(t) * math.cos(ang)])
    results = [
        {"image_id": 7, "category_id": 3, "score": 0.9, "bbox": [60, 50, 80, 60],
         "segmentation": {"size": [160, 200], "counts": counts}},
        {"image_id": 7, "category_id": 3, "score": 0.5, "bbox": [60, 50, 80, 60],
         "segmentation": {"size": [160, 200], "counts": encode_rle_counts(counts)}},
        {"image_id": 7, "category_id": 3, "score": 1.0, "segmentation": [poly.ravel().tolist()]},
        {"image_id": 8, "category_id": 4, "score": 0.25, "bbox": [10.0, 20.0, 30.0, 50.0]},
        {"image_id": 8, "category_id": 4, "score": 0.01, "bbox": [10.0, 20.0, 30.0, 50.0]},
    ]
    out = importers.detections_from_coco(results, {3: "TV", 4: "Chair"},
                                         image_names={7: "a.jpg"}, min_score=0.1)
    assert list(out) == ["a.jpg", "8"] and len(out["a.jpg"]) == 3 and len(out["8"]) == 1
    for d in out["a.jpg"][:2]:
        _same_ellipse(d["ellipse"], cx, cy, a, b, ang, 0.05, 0.01, math.radians(0.5))
    _same_ellipse(out["a.jpg"][2]["ellipse"], cx, cy, a, b, ang, 1e-9, 1e-4, 1e-9)
    box = out["8"][0]
    assert box["label"] == "Chair"
    # inscribed ellipse of x 10..40, y 20..70: the tall axis (25) is `a`
    _same_ellipse(box["ellipse"], 25.0, 45.0, 25.0, 15.0, math.pi / 2, 1e-12, 1e-12, 1e-12)
    # the sigma model: base / score
    assert [d["sigma"] for d in out["a.jpg"]] == pytest.approx([0.05 / 0.9, 0.05 / 0.5, 0.05])
    assert box["sigma"] == pytest.approx(0.1 / 0.25) and box["score"] == 0.25
    with pytest.raises(ValueError, match="category"):
        importers.detections_from_coco([{**results[3], "category_id": 9}], {4: "Chair"})


def test_polygon_moments_closed_forms() -> None:
    """A w x h rectangle: area w h, centroid its centre, covariance diag(w^2, h^2) / 12, in
    both orientations; two disjoint squares: the union's moments."""
    x0, y0, w, h = 3.0, -2.0, 8.0, 2.0
    rect = np.array([[x0, y0], [x0 + w, y0], [x0 + w, y0 + h], [x0, y0 + h]])
    for pts in (rect, rect[::-1]):
        area, c, cov = polygon_moments(pts)
        assert area == pytest.approx(w * h)
        np.testing.assert_allclose(c, [x0 + w / 2, y0 + h / 2], atol=1e-12)
        np.testing.assert_allclose(cov, np.diag([w * w, h * h]) / 12, atol=1e-12)
    sq = [[0, 0, 2, 0, 2, 2, 0, 2], [10, 0, 12, 0, 12, 2, 10, 2]]
    e = importers.ellipse_of_polygons(sq)
    # union: centroid (6, 1); var x = 4/12 + 25 (centres at 1 and 11), var y = 4/12
    assert (e.cx, e.cy) == pytest.approx((6.0, 1.0))
    assert e.a == pytest.approx(2 * math.sqrt(1 / 3 + 25)) and e.b == pytest.approx(
        2 * math.sqrt(1 / 3))


def test_recording_document_is_a_valid_recording_in_both_conventions(tmp_path: Path) -> None:
    """An AR log (OpenGL axes) and the same poses in OpenCV axes (times diag(1, -1, -1, 1),
    computed here) give the same recording once read by the server."""
    T = np.eye(4)
    T[:3, :3] = _rodrigues(*AXES[1])
    T[:3, 3] = TRANSLATIONS[1]
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    camera = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    det = {"label": "TV", "ellipse": {"cx": 300.0, "cy": 200.0, "a": 40.0, "b": 20.0,
                                      "angle": 0.1}, "sigma": 0.05, "score": 0.9}
    gl = importers.recording_document(camera, importers.read_ar_log(
        {"frames": [{"name": "f0", "transform": (T @ flip).T.tolist()}]}), {"f0": [det]},
        convention="opengl", name="room", holdout_every=2)
    cv = importers.recording_document(camera, {"f0": T}, {"f0": [det]}, name="room")
    json.dumps(gl)  # plain JSON
    a, b = recording_of(gl), recording_of(cv)
    np.testing.assert_allclose(a.frames[0].world_from_camera, T, atol=1e-12)
    np.testing.assert_allclose(b.frames[0].world_from_camera, T, atol=1e-12)
    assert a.observations == b.observations and a.name == "room"
