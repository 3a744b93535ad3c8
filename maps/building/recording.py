"""A recording: posed frames with object detections, the input of map building.

JSON document (what ``POST /v1/maps:build``, ``quadloc maps build`` and the SDK send):
docs/map_building.md, "The recording". Conventions: ``world_from_camera`` is the camera's pose
in the app's world frame (camera axes OpenCV), translation in metres, quaternion scalar first;
ellipses: centre px (origin top-left pixel corner), SEMI-axes px, angle radians; boxes
``[xmin, ymin, xmax, ymax]`` px become their inscribed axis-aligned ellipse; ``sigma`` as in
localize (factor std ``sqrt(sigma)``); detections with a ``track_id`` are grouped by it (per
label); ``refine_camera_poses`` (default true) refines the camera poses too, tied by the app's
relative poses with the noise ``odometry_noise`` (:class:`OdometryNoise`).

:func:`parse_recording` validates everything and raises :class:`RecordingError` listing every
problem as ``{"field": "frames[3].detections[0].ellipse.a", "message": ...}``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.names import text_problem
from quadloc.factors.rotations import (
    pose_matrix,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
)
from quadloc.maps.model import label_problem

__all__ = [
    "BuildLimits",
    "FrameRecord",
    "Observation",
    "OdometryNoise",
    "Recording",
    "RecordingError",
    "SizePrior",
    "parse_recording",
]


class RecordingError(ValueError):
    """Invalid recording; ``errors`` lists ``{"field", "message"}`` entries."""

    def __init__(self, errors: list[dict[str, str]]) -> None:
        self.errors = errors
        super().__init__("; ".join(f"{e['field']}: {e['message']}" for e in errors[:10]))


@dataclass(frozen=True)
class BuildLimits:
    """Size limits of one recording (the server's ``QUADLOC_BUILD_*`` settings)."""

    max_frames: int = 2000
    max_detections_per_frame: int = 64
    max_detections: int = 20_000


@dataclass(frozen=True)
class Observation:
    """One detection: ``frame`` index, index ``index`` within the frame, ``label``, ``ellipse``
    (px), optional ``sigma`` and ``track_id``."""

    frame: int
    index: int
    label: str
    ellipse: Ellipse
    sigma: float | None = None
    track_id: str | None = None


@dataclass(frozen=True)
class FrameRecord:
    """One frame: id, ``world_from_camera`` (4x4, app's world frame, OpenCV camera axes)."""

    frame_id: str
    world_from_camera: FloatArray


@dataclass(frozen=True)
class SizePrior:
    """Prior on every log semi-axis of a label's objects: ``N(log semi_axis_m, log_sigma^2)``."""

    semi_axis_m: float
    log_sigma: float


@dataclass(frozen=True)
class OdometryNoise:
    """Noise of the app's poses between two recorded frames, a random walk: over a path of
    ``d`` metres and ``n`` frame steps the relative pose has the std ``sqrt(r_m^2 d + r_s^2 n)``
    (rad, per rotation axis) and ``sqrt(t_m^2 d + t_s^2 n)`` (m, per translation axis), with
    ``r_m = rotation_rad_per_sqrt_m``, ``r_s = rotation_rad_per_step`` (the floor while turning
    on the spot), ``t_m = translation_m_per_sqrt_m``, ``t_s = translation_m_per_step``. The
    path-length terms make it independent of the frame rate. Defaults: a VIO drifting about
    1 cm and 0.3 deg over a metre (tuned on the bench's seed 0, bench/map_building.py)."""

    rotation_rad_per_sqrt_m: float = 0.005
    translation_m_per_sqrt_m: float = 0.01
    rotation_rad_per_step: float = 0.0005
    translation_m_per_step: float = 0.001

    def sigmas(self, distance_m: float, steps: int) -> FloatArray:
        """Between-factor stds ``[rotation x3 (rad), translation x3 (m)]`` (GTSAM Pose3 tangent
        order) over ``distance_m`` and ``steps``."""
        r = math.sqrt(self.rotation_rad_per_sqrt_m ** 2 * distance_m
                      + self.rotation_rad_per_step ** 2 * steps)
        t = math.sqrt(self.translation_m_per_sqrt_m ** 2 * distance_m
                      + self.translation_m_per_step ** 2 * steps)
        return np.array([r, r, r, t, t, t])


@dataclass(frozen=True)
class Recording:
    camera: Camera
    frames: tuple[FrameRecord, ...]
    observations: tuple[Observation, ...]
    name: str = "Built map"
    up_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    size_priors: Mapping[str, SizePrior] = field(default_factory=dict)
    refine_camera_poses: bool = True
    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)


def _bad(errors: list[dict[str, str]], field: str, message: str) -> None:
    errors.append({"field": field, "message": message})


def _num(errors: list[dict[str, str]], path: str, value: Any, positive: bool = False
         ) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        _bad(errors, path, "must be a finite number")
        return None
    if positive and value <= 0:
        _bad(errors, path, "must be > 0")
        return None
    return float(value)


def _vec(errors: list[dict[str, str]], path: str, value: Any, n: int) -> FloatArray | None:
    if not isinstance(value, list | tuple) or len(value) != n:
        _bad(errors, path, f"must be an array of {n} numbers")
        return None
    out = [_num(errors, f"{path}[{i}]", v) for i, v in enumerate(value)]
    return None if any(v is None for v in out) else np.array(out, dtype=float)


def _pose(errors: list[dict[str, str]], path: str, value: Any) -> FloatArray | None:
    if not isinstance(value, Mapping):
        _bad(errors, path, "must be an object with quaternion_wxyz and translation_m")
        return None
    q = _vec(errors, f"{path}.quaternion_wxyz", value.get("quaternion_wxyz"), 4)
    t = _vec(errors, f"{path}.translation_m", value.get("translation_m"), 3)
    if q is None or t is None:
        return None
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        _bad(errors, f"{path}.quaternion_wxyz",
             f"must have unit norm (got {np.linalg.norm(q):.6g})")
        return None
    return pose_matrix(rotation_from_quaternion_wxyz(q / np.linalg.norm(q)), t)


def _ellipse(errors: list[dict[str, str]], path: str, det: Mapping[str, Any]) -> Ellipse | None:
    has_e, has_b = det.get("ellipse") is not None, det.get("box") is not None
    if has_e == has_b:
        _bad(errors, path, "give exactly one of ellipse or box")
        return None
    if has_b:
        box = _vec(errors, f"{path}.box", det["box"], 4)
        if box is None:
            return None
        if not (box[2] > box[0] and box[3] > box[1]):
            _bad(errors, f"{path}.box", "must have xmax > xmin and ymax > ymin")
            return None
        return Ellipse.from_bbox(*box)
    e = det["ellipse"]
    if not isinstance(e, Mapping):
        _bad(errors, f"{path}.ellipse", "must be {cx, cy, a, b, angle}")
        return None
    vals = [_num(errors, f"{path}.ellipse.{k}", e.get(k), positive=k in ("a", "b"))
            for k in ("cx", "cy", "a", "b", "angle")]
    nums = [v for v in vals if v is not None]
    return Ellipse(*nums) if len(nums) == len(vals) else None


def _text(errors: list[dict[str, str]], field: str, value: object, *,
          label: bool = False) -> bool:
    """Check a text (or integer id) of the recording that is stored (in the map or the job's
    report) and echoed: :func:`quadloc.maps.model.label_problem` for what becomes a map label
    or name (``label``), :func:`quadloc.factors.names.text_problem` otherwise; False and an
    error naming ``field`` when refused (422 at intake, not a job failing at 95 %)."""
    if not isinstance(value, str):
        return True
    problem = label_problem(value) if label else text_problem(value)
    if problem is not None:
        _bad(errors, field, problem)
        return False
    return True


def parse_recording(data: Any, limits: BuildLimits | None = None) -> Recording:
    """Validate a recording document (module docstring) into a :class:`Recording`."""
    lim = limits or BuildLimits()
    errors: list[dict[str, str]] = []
    if not isinstance(data, Mapping):
        raise RecordingError([{"field": "body", "message": "must be a JSON object"}])
    intr = data.get("intrinsics")
    camera = None
    if not isinstance(intr, Mapping):
        _bad(errors, "intrinsics", "required: {fx, fy, cx, cy, width, height}")
    else:
        v = {k: _num(errors, f"intrinsics.{k}", intr.get(k), positive=k not in ("cx", "cy"))
             for k in ("fx", "fy", "cx", "cy", "width", "height")}
        n = {k: x for k, x in v.items() if x is not None}
        if len(n) == len(v):
            camera = Camera(n["fx"], n["fy"], n["cx"], n["cy"], int(n["width"]),
                            int(n["height"]))
    frames_in = data.get("frames")
    if not isinstance(frames_in, list) or not frames_in:
        _bad(errors, "frames", "must be a non-empty array")
        frames_in = []
    elif len(frames_in) > lim.max_frames:
        _bad(errors, "frames", f"at most {lim.max_frames} frames")
        frames_in = []
    frames: list[FrameRecord] = []
    obs: list[Observation] = []
    n_det = 0
    for fi, f in enumerate(frames_in):
        path = f"frames[{fi}]"
        if not isinstance(f, Mapping):
            _bad(errors, path, "must be an object")
            continue
        fid = f.get("frame_id", str(fi))
        if not isinstance(fid, str | int) or isinstance(fid, bool) or len(str(fid)) > 128:
            _bad(errors, f"{path}.frame_id", "must be a string of at most 128 characters")
        else:
            _text(errors, f"{path}.frame_id", fid)
        T = _pose(errors, f"{path}.world_from_camera", f.get("world_from_camera"))
        dets = f.get("detections", [])
        if not isinstance(dets, list):
            _bad(errors, f"{path}.detections", "must be an array")
            dets = []
        if len(dets) > lim.max_detections_per_frame:
            _bad(errors, f"{path}.detections",
                 f"at most {lim.max_detections_per_frame} detections")
            dets = []
        n_det += len(dets)
        if n_det > lim.max_detections:
            _bad(errors, "frames", f"at most {lim.max_detections} detections in total")
            break
        frames.append(FrameRecord(str(fid), T if T is not None else np.eye(4)))
        for di, d in enumerate(dets):
            dp = f"{path}.detections[{di}]"
            if not isinstance(d, Mapping):
                _bad(errors, dp, "must be an object")
                continue
            label = d.get("label")
            if not isinstance(label, str) or not 0 < len(label) <= 128:
                _bad(errors, f"{dp}.label",
                     "must be a non-empty string of at most 128 characters")
            elif not _text(errors, f"{dp}.label", label, label=True):
                label = None
            ell = _ellipse(errors, dp, d)
            sigma = d.get("sigma")
            if sigma is not None:
                sigma = _num(errors, f"{dp}.sigma", sigma, positive=True)
            track = d.get("track_id")
            if track is not None and (not isinstance(track, str | int) or isinstance(track, bool)
                                      or len(str(track)) > 128):
                _bad(errors, f"{dp}.track_id", "must be a string")
                track = None
            elif not _text(errors, f"{dp}.track_id", track):
                track = None
            if ell is not None and isinstance(label, str):
                obs.append(Observation(len(frames) - 1, di, label, ell, sigma,
                                       None if track is None else str(track)))
    name = data.get("name", "Built map")
    if not isinstance(name, str) or not 0 < len(name) <= 256:
        _bad(errors, "name", "must be a non-empty string")
    else:
        _text(errors, "name", name, label=True)
    up = data.get("up_axis", [0.0, 0.0, 1.0])
    upv = _vec(errors, "up_axis", up, 3)
    priors: dict[str, SizePrior] = {}
    sp = data.get("size_priors", {}) or {}
    if not isinstance(sp, Mapping):
        _bad(errors, "size_priors", "must be an object label -> {semi_axis_m, log_sigma}")
        sp = {}
    for label, p in sp.items():
        path = f"size_priors.{label}"
        if not _text(errors, "size_priors", label, label=True):
            continue
        if not isinstance(p, Mapping):
            _bad(errors, path, "must be {semi_axis_m, log_sigma}")
            continue
        a = _num(errors, f"{path}.semi_axis_m", p.get("semi_axis_m"), positive=True)
        s = _num(errors, f"{path}.log_sigma", p.get("log_sigma", 0.5), positive=True)
        if a is not None and s is not None:
            priors[str(label)] = SizePrior(a, s)
    refine = data.get("refine_camera_poses", True)
    if not isinstance(refine, bool):
        _bad(errors, "refine_camera_poses", "must be a boolean")
    odo = data.get("odometry_noise", {}) or {}
    noise = OdometryNoise()
    if not isinstance(odo, Mapping):
        _bad(errors, "odometry_noise", "must be an object")
    else:
        known = set(OdometryNoise.__dataclass_fields__)
        for key in sorted(set(odo) - known):
            _bad(errors, f"odometry_noise.{key}", f"unknown; expected one of {sorted(known)}")
        vals: dict[str, float] = {}
        for key in known & set(odo):
            x = _num(errors, f"odometry_noise.{key}", odo[key])
            if x is not None and not 0 <= x <= 10:
                _bad(errors, f"odometry_noise.{key}", "must be in [0, 10]")
            elif x is not None:
                vals[key] = x
        noise = OdometryNoise(**{**noise.__dict__, **vals})
        if not errors and (noise.rotation_rad_per_step <= 0 or noise.translation_m_per_step <= 0):
            _bad(errors, "odometry_noise", "the per-step floors rotation_rad_per_step and "
                 "translation_m_per_step must be > 0")
    if errors:
        raise RecordingError(errors)
    assert camera is not None and upv is not None
    return Recording(camera, tuple(frames), tuple(obs), name, tuple(upv.tolist()), priors,
                     bool(refine), noise)


def recording_to_dict(camera: Camera,
                      frames: Sequence[tuple[str, FloatArray, Sequence[dict[str, Any]]]],
                      **extra: Any) -> dict[str, Any]:
    """A recording document from ``(frame_id, world_from_camera 4x4, detections)`` triples
    (detections already in the JSON form). Used by the benchmark and the tests."""
    out = {"intrinsics": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                          "width": camera.width, "height": camera.height},
           "frames": [{"frame_id": fid,
                       "world_from_camera": {
                           "quaternion_wxyz": quaternion_wxyz_from_rotation(T[:3, :3]).tolist(),
                           "translation_m": np.asarray(T[:3, 3], float).tolist()},
                       "detections": list(dets)} for fid, T, dets in frames]}
    out.update(extra)
    return out
