"""A recording: posed frames with object detections, the input of map building (domain types).

The JSON document (what ``POST /v1/maps:build``, ``quadloc maps build`` and the SDK send) is the
wire model ``quadloc.service.schemas.recording.RecordingIn`` (docs/map_building.md, "The
recording"); the application converts it into a :class:`Recording`: ``world_from_camera`` the
camera's pose in the app's world frame (camera axes OpenCV), translation in metres; ellipses:
centre px (origin top-left pixel corner), SEMI-axes px, angle radians; ``sigma`` as in localize
(factor std ``sqrt(sigma)``); detections with a ``track_id`` are grouped by it (per label);
``refine_camera_poses`` refines the camera poses too, tied by the app's relative poses with the
noise ``odometry_noise`` (:class:`OdometryNoise`). Frames :func:`held_out` of the build are
left out of the :class:`Recording` (each :class:`FrameRecord` keeps its position in the
document, ``source_index``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import quaternion_wxyz_from_rotation

__all__ = [
    "BuildLimits",
    "FrameRecord",
    "Observation",
    "OdometryNoise",
    "Recording",
    "SizePrior",
    "held_out",
    "recording_to_dict",
]


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
    """One frame: id, ``world_from_camera`` (4x4, app's world frame, OpenCV camera axes) and
    its position in the recording document (``source_index``; None: its position here)."""

    frame_id: str
    world_from_camera: FloatArray
    source_index: int | None = None


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
    #: What the build report should tell the user about the recording itself.
    warnings: tuple[str, ...] = ()


def held_out(n_frames: int, every: int | None) -> BoolArray:
    """THE holdout rule: frame ``i`` of ``n_frames`` is held out of the build (kept for
    calibration) iff ``every`` is set and ``i % every == every - 1``; shape ``(n_frames,)``."""
    i = np.arange(n_frames)
    out: BoolArray = (i % every == every - 1) if every else np.zeros(n_frames, dtype=bool)
    return out


def recording_to_dict(camera: Camera,
                      frames: Sequence[tuple[str, FloatArray, Sequence[dict[str, Any]]]],
                      **extra: Any) -> dict[str, Any]:
    """A recording document (``quadloc.service.schemas.recording.RecordingIn``, OpenCV axes)
    from ``(frame_id, world_from_camera 4x4, detections)`` triples (detections already in the
    JSON form). Used by the benchmark and the tests."""
    out = {"camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                      "width": camera.width, "height": camera.height},
           "frames": [{"frame_id": fid,
                       "world_from_camera": {
                           "quaternion_wxyz": quaternion_wxyz_from_rotation(T[:3, :3]).tolist(),
                           "translation_m": np.asarray(T[:3, 3], float).tolist()},
                       "detections": list(dets)} for fid, T, dets in frames]}
    out.update(extra)
    return out
