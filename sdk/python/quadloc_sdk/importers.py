"""Importers: what users have -> a QuadLoc recording (the body of ``POST /v1/maps:build``).

Pure parsing (numpy; no server, no gtsam, no OpenCV): apps and ``quadloc import-recording`` use
the same functions. docs/map_building.md, "Importing your data", shows them end to end.

Camera trajectories (every reader returns ``world_from_camera`` 4x4 poses in metres, keyed by
the frame's name, in the camera axes stated):

* TUM RGB-D (:func:`read_tum_trajectory`): lines ``timestamp tx ty tz qx qy qz qw`` (``#``
  comments), the camera's pose in the world (OpenCV camera axes: +X right, +Y down, +Z
  forward); keys are the timestamps as written. :func:`match_timestamps` pairs them with the
  image list (``rgb.txt``: ``timestamp filename``).
* COLMAP text model (:func:`read_colmap_images`, :func:`read_colmap_camera`): ``images.txt``
  stores ``camera_from_world`` (``QW QX QY QZ TX TY TZ``), inverted here; keys are the image
  names. ``cameras.txt``: ``PINHOLE`` / ``SIMPLE_PINHOLE`` only (detections must be
  undistorted). COLMAP's pixel origin is the top-left image corner, as QuadLoc's.
* ARKit / ARCore JSON log (:func:`read_ar_log`): ``{"frames": [{"name"?, "timestamp"?,
  "transform": [[c0], [c1], [c2], [c3]]}]}`` (ARKit ``ARFrame.camera.transform``: 4 COLUMNS)
  or ``"matrix_column_major": [16 numbers]`` (ARCore ``Pose.toMatrix``); OpenGL camera axes
  (+Y up, -Z forward): the recording is written with ``convention: "opengl"``.

Detections in the COCO results format (:func:`detections_from_coco`): ``[{"image_id",
"category_id", "score", "bbox": [x, y, w, h], "segmentation"?}]``; the segmentation is a
polygon list or an RLE mask (``{"size": [h, w], "counts": [...]}`` or the compressed string
form), decoded here (no pycocotools). Each becomes an ellipse: a mask by its moment-matched
ellipse (:func:`quadloc_sdk.geometry.ellipse_from_mask`), a polygon by its area moments
(:func:`ellipse_of_polygons`), a box alone by its inscribed ellipse.

The sigma model (:func:`coco_sigma`):
``sigma = SIGMA_BASE[shape] / max(score, MIN_SCORE_FOR_SIGMA)`` with
``SIGMA_BASE = {"mask": 0.05, "polygon": 0.05, "box": 0.1}``: ``sigma`` is the expected
level-set distance of the ellipse (docs/api.md), a mask or polygon outlines the object (about
5 % of its size), a box loses its orientation and shape (twice that), and a lower detector
score means a proportionally less certain outline. Only the ratios between detections weigh
the refinement (the reported covariance is rescaled by the residuals' variance), and the
map's calibration (``quadloc calibrate``) absorbs the rest.
"""

from __future__ import annotations

import gzip
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from quadloc_sdk.geometry import (
    ellipse_from_box,
    ellipse_from_mask,
    ellipse_from_moments,
    invert_pose,
    matrix_from_quaternion_wxyz,
    polygon_moments,
    quaternion_wxyz_from_xyzw,
)
from quadloc_sdk.models import Ellipse

__all__ = [
    "MIN_SCORE_FOR_SIGMA",
    "SIGMA_BASE",
    "coco_sigma",
    "decode_coco_rle",
    "detections_from_coco",
    "ellipse_of_polygons",
    "match_timestamps",
    "read_ar_log",
    "read_colmap_camera",
    "read_colmap_images",
    "read_json",
    "read_tum_trajectory",
    "recording_document",
]

#: ``sigma`` of a detection with score 1, by the shape it came from (module docstring).
SIGMA_BASE: dict[str, float] = {"mask": 0.05, "polygon": 0.05, "box": 0.1}
#: Scores below this count as this in the sigma model (caps sigma at 20 x its base).
MIN_SCORE_FOR_SIGMA = 0.05

Pose = np.ndarray  # 4x4 float64 world_from_camera


def _lines(text: str) -> Iterable[tuple[int, list[str]]]:
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            yield n, s.split()


def _pose(quaternion_wxyz: Sequence[float] | np.ndarray, translation: Sequence[float],
          where: str) -> Pose:
    q = np.asarray(quaternion_wxyz, dtype=float)
    n = float(np.linalg.norm(q))
    if not (np.all(np.isfinite(q)) and abs(n - 1.0) <= 1e-3):
        raise ValueError(f"{where}: quaternion norm {n:.6g}, expected 1")
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion_wxyz(q / n)
    T[:3, 3] = np.asarray(translation, dtype=float)
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{where}: translation is not finite")
    return T


def read_tum_trajectory(text: str) -> dict[str, Pose]:
    """TUM RGB-D trajectory text -> ``{timestamp (as written): world_from_camera 4x4}``
    (OpenCV camera axes). Raises ``ValueError`` naming the line of a malformed entry."""
    out: dict[str, Pose] = {}
    for n, parts in _lines(text):
        if len(parts) != 8:
            raise ValueError(f"line {n}: expected 'timestamp tx ty tz qx qy qz qw', got "
                             f"{len(parts)} values")
        try:
            v = [float(x) for x in parts[1:]]
        except ValueError as exc:
            raise ValueError(f"line {n}: not a number ({exc})") from exc
        out[parts[0]] = _pose(quaternion_wxyz_from_xyzw(np.array(v[3:])), v[:3], f"line {n}")
    return out


def match_timestamps(poses: Mapping[str, Pose], images_text: str, max_dt_s: float = 0.02
                     ) -> dict[str, Pose]:
    """Pair a TUM trajectory (keys: timestamps) with an image list (``rgb.txt``: lines
    ``timestamp filename``): ``{filename: world_from_camera}`` of the pose nearest in time,
    images without a pose within ``max_dt_s`` seconds left out."""
    stamps = np.array([float(k) for k in poses])
    values = list(poses.values())
    out: dict[str, Pose] = {}
    if not len(stamps):
        return out
    for n, parts in _lines(images_text):
        if len(parts) < 2:
            raise ValueError(f"images line {n}: expected 'timestamp filename'")
        k = int(np.argmin(np.abs(stamps - float(parts[0]))))
        if abs(stamps[k] - float(parts[0])) <= max_dt_s:
            out[parts[1]] = values[k]
    return out


def read_colmap_images(text: str) -> dict[str, Pose]:
    """COLMAP ``images.txt`` -> ``{image name: world_from_camera 4x4}``: COLMAP stores
    ``camera_from_world`` (``QW QX QY QZ TX TY TZ``), inverted here. Each image takes two lines
    (the second, its 2-D points, may be empty: COLMAP writes an empty line)."""
    out: dict[str, Pose] = {}
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        s = lines[k].strip()
        if not s or s.startswith("#"):
            k += 1
            continue
        parts = s.split()
        if len(parts) < 10:
            raise ValueError(f"line {k + 1}: expected 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID "
                             "NAME'")
        v = [float(x) for x in parts[1:8]]
        camera_from_world = _pose(v[:4], v[4:7], f"line {k + 1}")
        out[" ".join(parts[9:])] = invert_pose(camera_from_world)
        k += 2  # the points line follows
    return out


def read_colmap_camera(text: str, camera_id: int | None = None) -> dict[str, float | int]:
    """COLMAP ``cameras.txt`` -> QuadLoc's camera ``{fx, fy, cx, cy, width, height}`` (the
    first camera, or ``camera_id``). Only undistorted models (``PINHOLE``, ``SIMPLE_PINHOLE``)."""
    for n, parts in _lines(text):
        cid, model, w, h = int(parts[0]), parts[1], int(parts[2]), int(parts[3])
        if camera_id is not None and cid != camera_id:
            continue
        p = [float(x) for x in parts[4:]]
        if model == "PINHOLE" and len(p) == 4:
            fx, fy, cx, cy = p
        elif model == "SIMPLE_PINHOLE" and len(p) == 3:
            fx = fy = p[0]
            cx, cy = p[1], p[2]
        else:
            raise ValueError(f"line {n}: camera model {model} with {len(p)} parameters is not "
                             "supported: undistort the images (colmap image_undistorter) and "
                             "use its PINHOLE cameras.txt")
        return {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": w, "height": h}
    raise ValueError("no camera" if camera_id is None else f"no camera {camera_id}")


def read_ar_log(document: Any) -> dict[str, Pose]:
    """ARKit / ARCore JSON log (module docstring) -> ``{name: world_from_camera 4x4}`` in
    OpenGL camera axes (send with ``convention="opengl"``); a frame without ``name`` is named
    by its ``timestamp``, else its position."""
    frames = document.get("frames") if isinstance(document, Mapping) else document
    if not isinstance(frames, list):
        raise ValueError("frames: expected a list of frames")
    out: dict[str, Pose] = {}
    for k, f in enumerate(frames):
        where = f"frames[{k}]"
        if not isinstance(f, Mapping):
            raise ValueError(f"{where}: expected an object")
        if "transform" in f:
            cols = np.asarray(f["transform"], dtype=float)
            if cols.shape != (4, 4):
                raise ValueError(f"{where}.transform: expected 4 columns of 4 numbers")
            T = cols.T
        elif "matrix_column_major" in f:
            v = np.asarray(f["matrix_column_major"], dtype=float)
            if v.shape != (16,):
                raise ValueError(f"{where}.matrix_column_major: expected 16 numbers")
            T = v.reshape(4, 4).T
        else:
            raise ValueError(f"{where}: give 'transform' (4 columns) or 'matrix_column_major'")
        if not (np.all(np.isfinite(T)) and np.allclose(T[3], [0, 0, 0, 1], atol=1e-6)):
            raise ValueError(f"{where}: not a finite rigid transform (last row [0, 0, 0, 1])")
        name = f.get("name", f.get("timestamp", k))
        out[str(name)] = T
    return out


# --------------------------------------------------------------------------- COCO


def decode_coco_rle(rle: Mapping[str, Any]) -> np.ndarray:
    """A COCO RLE mask ``{"size": [h, w], "counts": list | str}`` -> bool array (h, w).

    Runs alternate 0s and 1s starting with 0s over the pixels in COLUMN-major order; the string
    form is COCO's compressed one (pycocotools ``rleFrString``: 6-bit chars from ``'0'``, 5
    value bits and a continuation bit, sign-extended, each count after the second stored as the
    difference to the count two before)."""
    h, w = (int(x) for x in rle["size"])
    counts_in = rle["counts"]
    if isinstance(counts_in, str | bytes):
        s = counts_in.decode() if isinstance(counts_in, bytes) else counts_in
        counts: list[int] = []
        p = 0
        while p < len(s):
            x, k, more = 0, 0, True
            while more:
                c = ord(s[p]) - 48
                x |= (c & 0x1F) << (5 * k)
                more = bool(c & 0x20)
                p += 1
                k += 1
                if not more and (c & 0x10):
                    x |= -1 << (5 * k)
            if len(counts) > 2:
                x += counts[-2]
            counts.append(x)
    else:
        counts = [int(c) for c in counts_in]
    if any(c < 0 for c in counts) or sum(counts) != h * w:
        raise ValueError(f"counts: runs must be >= 0 and add up to h * w = {h * w}, got "
                         f"{sum(counts)}")
    values = np.zeros(len(counts), dtype=bool)
    values[1::2] = True
    flat = np.repeat(values, counts)
    return flat.reshape(w, h).T


def coco_sigma(shape: str, score: float | None) -> float:
    """The sigma model (module docstring): ``SIGMA_BASE[shape] / max(score, MIN_SCORE_FOR_SIGMA)``
    (score None counts as 1)."""
    s = 1.0 if score is None else float(score)
    return SIGMA_BASE[shape] / max(min(s, 1.0), MIN_SCORE_FOR_SIGMA)


def _coco_ellipse(det: Mapping[str, Any], where: str) -> tuple[Ellipse, str]:
    seg = det.get("segmentation")
    if isinstance(seg, Mapping):
        return ellipse_from_mask(decode_coco_rle(seg)), "mask"
    if isinstance(seg, list) and seg:
        return ellipse_of_polygons(seg, where), "polygon"
    bbox = det.get("bbox")
    if not (isinstance(bbox, list) and len(bbox) == 4):
        raise ValueError(f"{where}: needs a 'bbox' [x, y, w, h] or a 'segmentation'")
    x, y, bw, bh = (float(v) for v in bbox)
    return ellipse_from_box((x, y, x + bw, y + bh)), "box"


def ellipse_of_polygons(parts: Sequence[Sequence[float]], where: str = "segmentation"
                        ) -> Ellipse:
    """The moment-matched ellipse of a COCO polygon segmentation: one or more disjoint parts,
    each a flat ``[x1, y1, x2, y2, ...]`` (px, top-left pixel corner origin); the union's
    moments are the parts' area-weighted ones."""
    m = [polygon_moments(np.asarray(p, dtype=float).reshape(-1, 2)) for p in parts]
    area = sum(a for a, _, _ in m)
    if not area > 0:
        raise ValueError(f"{where}.segmentation: zero area")
    mean = np.sum([a * c for a, c, _ in m], axis=0) / area
    second = np.sum([a * (S + np.outer(c, c)) for a, c, S in m], axis=0) / area
    return ellipse_from_moments(mean, second - np.outer(mean, mean), where)


def detections_from_coco(
    results: Sequence[Mapping[str, Any]], categories: Mapping[int, str], *,
    image_names: Mapping[int, str] | None = None, min_score: float = 0.0,
) -> dict[str, list[dict[str, Any]]]:
    """COCO results -> ``{image: [wire detection, ...]}`` (``{"label", "ellipse", "sigma",
    "score"}``, the recording's detection form). ``categories``: ``category_id -> label``;
    ``image_names``: ``image_id -> file name`` (the COCO ``images`` list), else keys are the
    image ids as text. Detections below ``min_score`` are left out."""
    out: dict[str, list[dict[str, Any]]] = {}
    for k, det in enumerate(results):
        where = f"results[{k}]"
        score = det.get("score")
        if score is not None and float(score) < min_score:
            continue
        cid = int(det["category_id"])
        if cid not in categories:
            raise ValueError(f"{where}.category_id: unknown category {cid}")
        e, shape = _coco_ellipse(det, where)
        image = (image_names or {}).get(int(det["image_id"]), str(det["image_id"]))
        d: dict[str, Any] = {"label": categories[cid],
                             "ellipse": {"cx": e.cx, "cy": e.cy, "a": e.a, "b": e.b,
                                         "angle": e.angle},
                             "sigma": coco_sigma(shape, score)}
        if score is not None:
            d["score"] = min(max(float(score), 0.0), 1.0)
        out.setdefault(image, []).append(d)
    return out


def recording_document(
    camera: Mapping[str, float | int], poses: Mapping[str, Pose],
    detections: Mapping[str, Sequence[Mapping[str, Any]]], *, convention: str = "opencv",
    **options: Any,
) -> dict[str, Any]:
    """A recording (the body of ``POST /v1/maps:build``): one frame per pose, in the poses'
    order, named by its key, pose as a ``matrix`` in ``convention`` axes, with the detections
    of the same key (none if absent); ``options``: the recording's build options
    (``name``, ``holdout_every``, ``size_priors``...)."""
    frames = [{"frame_id": name, "world_from_camera": {"matrix": np.asarray(T).tolist()},
               "detections": [dict(d) for d in detections.get(name, ())]}
              for name, T in poses.items()]
    if not frames:
        raise ValueError("poses: no frame")
    return {"camera": dict(camera), "convention": convention, "frames": frames, **options}


def read_json(path: str | Path) -> Any:
    """A JSON file (``.gz`` decompressed)."""
    p = Path(path)
    if p.suffix == ".gz":
        return json.loads(gzip.decompress(p.read_bytes()))
    return json.loads(p.read_text(encoding="utf-8"))

