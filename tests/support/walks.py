"""Camera trajectories of the tests and benchmarks, and the drifting odometry of an AR app.

* :func:`make_walk`: 30 Hz ``world_from_camera`` poses through key poses (smooth start / stop
  on long gaps), and :func:`simulate_odometry`: the app's ``odom_from_camera`` poses along it
  (random frame offset, gyro bias, 1 % scale error, noise): the tracking sessions' walks.
* :func:`chess_walk`: the tests' and benchmarks' walk through the real Chess poses, with its
  drifting odometry and simulated detections (one seeded generator: odometry first, then each
  frame's detections), as :class:`ChessWalk`.
* :func:`resampled_walk`: ``n`` poses along key poses (each key pose kept, slerp between), and
  :func:`drifting_odometry`: app poses chained from noisy relative motions, starting at the
  true first pose: the map-building recordings.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quadloc.factors.camera import Camera
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose, pose_matrix, rotation_angle, snap_to_rotation
from quadloc.maps.compiled import CompiledMap, compile_map
from quadloc.service.localization.types import Detection
from quadloc.service.tracking.session import FrameInput
from tests.support.reference_data import load_chess_map, load_chess_poses
from tests.support.simulate import SimulationConfig, simulate_frame

__all__ = ["HZ", "ChessWalk", "chess_walk", "drifting_odometry", "frame_json", "make_walk",
           "resampled_walk", "simulate_odometry"]


HZ = 30.0


def _log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vector ``w`` (rad) of ``R`` (``R = exp([w]x)``): the interpolation's log map."""
    c = max(-1.0, min(1.0, (np.trace(R) - 1) / 2))
    a = math.acos(c)
    if a < 1e-9:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return a * w / (2 * math.sin(a))


def _exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation ``exp([w]x)`` (rad): the rotation block of the shared SE(3) exponential."""
    return expmap_pose3(np.concatenate([w, np.zeros(3)]))[:3, :3]


def make_walk(keyposes: list[np.ndarray], speed_m_s: float = 0.4) -> list[np.ndarray]:
    """30 Hz world_from_camera poses through the key poses (module docstring), travelled at
    <= ``speed_m_s`` and <= 45 deg/s."""
    out: list[np.ndarray] = []
    for a, b in itertools.pairwise(keyposes):
        d = float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
        ang = float(rotation_angle(a[:3, :3], b[:3, :3]))
        dur = max(0.1, d / speed_m_s, ang / math.radians(45))
        n = max(1, round(dur * HZ))
        w = _log_so3(a[:3, :3].T @ b[:3, :3])
        for i in range(n):
            s = i / n
            h = 3 * s * s - 2 * s ** 3  # smooth start/stop on long gaps
            s2 = h if dur > 0.15 else s
            out.append(pose_matrix(a[:3, :3] @ _exp_so3(s2 * w),
                                   (1 - s2) * a[:3, 3] + s2 * b[:3, 3]))
    out.append(keyposes[-1])
    return out


def simulate_odometry(walk: list[np.ndarray], rng: np.random.Generator) -> list[np.ndarray]:
    """odom_from_camera poses with drift (module docstring)."""
    offset = pose_matrix(_exp_so3(rng.normal(size=3)), rng.normal(size=3) * 2)
    bias = rng.normal(size=3)
    bias *= math.radians(0.03) / np.linalg.norm(bias)
    scale = 1.0 + 0.01 * (1 if rng.random() < 0.5 else -1)
    dt = 1.0 / HZ
    odom = [offset @ walk[0]]
    for a, b in itertools.pairwise(walk):
        rel = invert_pose(a) @ b
        d = float(np.linalg.norm(rel[:3, 3]))
        R = rel[:3, :3] @ _exp_so3(bias * dt + rng.normal(size=3) * math.radians(0.1)
                                   * math.sqrt(dt))
        t = rel[:3, 3] * scale + rng.normal(size=3) * 0.005 * math.sqrt(d)
        odom.append(odom[-1] @ pose_matrix(snap_to_rotation(R), t))
    return odom


@dataclass(frozen=True)
class ChessWalk:
    """A simulated 30 Hz walk through the Chess room (:func:`chess_walk`).

    Attributes:
        compiled: the Chess map, compiled.
        camera: the Chess camera (px).
        poses: true ``world_from_camera`` 4x4 poses, one per frame.
        odometry: the app's drifting ``odom_from_camera`` 4x4 poses, one per frame.
        frames: the session frames (detections, odometry, timestamp ``i / HZ`` s, frame id
            ``str(i)``), after the walk's ``keep`` rule.
    """

    compiled: CompiledMap
    camera: Camera
    poses: list[np.ndarray]
    odometry: list[np.ndarray]
    frames: list[FrameInput]


def chess_walk(n_frames: int, seed: int, start: int = 0,
               config: SimulationConfig | None = None,
               keep: Callable[[int, list[Detection]], list[Detection]] | None = None,
               ) -> ChessWalk:
    """Frames ``start .. start + n_frames`` of the walk through the real Chess poses
    (:func:`make_walk`), the odometry along them (:func:`simulate_odometry`) and each frame's
    simulated detections, all drawn from ``default_rng(seed)`` in that order.

    ``keep(i, detections)`` returns the detections frame ``i`` (counted from ``start``) keeps:
    a sparse or blind stretch without changing what is drawn (default: all).
    """
    compiled = compile_map(load_chess_map())
    camera, cfw, _ = load_chess_poses()
    poses = make_walk([invert_pose(T) for T in cfw])[start:start + n_frames]
    rng = np.random.default_rng(seed)
    odometry = simulate_odometry(poses, rng)
    frames = []
    for i, (T, To) in enumerate(zip(poses, odometry, strict=True)):
        dets = list(simulate_frame(compiled, camera, T, rng, config or SimulationConfig())
                    .detections)
        frames.append(FrameInput(keep(i, dets) if keep else dets, To, i / HZ, str(i)))
    return ChessWalk(compiled, camera, poses, odometry, frames)


def frame_json(frame: FrameInput) -> dict:
    """A session frame as the API's JSON (``POST /v1/sessions/{id}/frames``)."""
    return {"detections": [{"ellipse": {"cx": d.ellipse.cx, "cy": d.ellipse.cy,
                                        "a": d.ellipse.a, "b": d.ellipse.b,
                                        "angle": d.ellipse.angle},
                            "label": d.label, "sigma": d.sigma} for d in frame.detections],
            "odom_from_camera": {"matrix": frame.odom_from_camera.tolist()},
            "timestamp": frame.timestamp, "frame_id": frame.frame_id}


ROT_NOISE_DEG = 0.05


TRANS_NOISE_REL = 0.01


TRANS_NOISE_ABS_M = 0.001


def _slerp(R0: np.ndarray, R1: np.ndarray, s: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation, Slerp

    return Slerp([0, 1], Rotation.from_matrix([R0, R1]))(s).as_matrix()


def resampled_walk(poses: list[np.ndarray], n: int) -> list[np.ndarray]:
    """``n`` world_from_camera poses along the real poses (each real pose included)."""
    k = len(poses)
    if n <= k:
        return [poses[i] for i in np.linspace(0, k - 1, n).astype(int)]
    per = (n - k) / (k - 1)
    out = []
    acc = 0.0
    for i in range(k - 1):
        out.append(poses[i])
        acc += per
        m = round(acc)
        acc -= m
        for j in range(m):
            s = (j + 1) / (m + 1)
            R = _slerp(poses[i][:3, :3], poses[i + 1][:3, :3], s)
            out.append(pose_matrix(R, (1 - s) * poses[i][:3, 3] + s * poses[i + 1][:3, 3]))
    out.append(poses[-1])
    return out[:n]


def drifting_odometry(true_poses: list[np.ndarray], rng: np.random.Generator) -> list[np.ndarray]:
    """Drifting app poses: noisy relative motions chained from the true first pose."""
    out = [true_poses[0].copy()]
    for a, b in itertools.pairwise(true_poses):
        rel = np.linalg.inv(a) @ b
        step = float(np.linalg.norm(rel[:3, 3]))
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        xi = np.zeros(6)
        xi[:3] = axis * math.radians(rng.normal(0, ROT_NOISE_DEG))
        noisy = rel @ expmap_pose3(xi)
        noisy[:3, 3] += rng.normal(0, TRANS_NOISE_REL * step + TRANS_NOISE_ABS_M, 3)
        out.append(out[-1] @ noisy)
    return out
