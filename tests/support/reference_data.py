"""Load the project's real reference data, shipped in the checkout under ``tests/support/data/``.

``tests/support/data/README.md`` gives the provenance of each file. The data is not part of the
installed package (the demo map ``maps/data/chess.json`` is): tests, benchmarks and docs examples
read it from the source tree, never from outside the checkout.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import DegenerateProjectionError, Ellipse
from quadloc.factors.rotations import invert_pose, pose_matrix, snap_to_rotation
from quadloc.maps.model import SceneMap, scene_map_from_chess

DATA_DIR = Path(__file__).resolve().parent / "data"
CHESS_SCENE_PATH = DATA_DIR / "chess_scene.json"
CHESS_POSES_PATH = DATA_DIR / "chess_test_poses.json"


def load_chess_poses(
    path: Path = CHESS_POSES_PATH,
) -> tuple[Camera, list[np.ndarray], list[str]]:
    """The real Chess test poses: ``(camera, camera_from_world 4x4 list, frame names)``.

    The file's ``R, t`` are camera_from_world (``x_cam = R x_world + t``, OpenCV axes); each ``R``
    is snapped to the nearest rotation (the tracker's matrices are orthonormal only to ~2e-4).
    """
    data = json.loads(Path(path).read_text())
    camera = Camera.from_matrix(np.array(data["K"]), data["width"], data["height"])
    poses = [pose_matrix(snap_to_rotation(np.array(f["R"])), f["t"]) for f in data["frames"]]
    names = [f"{f['sequence']}/{f['frame']}" for f in data["frames"]]
    return camera, poses, names


def load_chess_scene_json(path: Path = CHESS_SCENE_PATH) -> dict:
    """The raw Chess scene document (authors' format; see
    ``quadloc.maps.model.scene_map_from_chess``)."""
    return json.loads(Path(path).read_text())


def load_chess_map(path: Path = CHESS_SCENE_PATH) -> SceneMap:
    """The Chess ellipsoid map (11 objects, +Z up) via the maps importer."""
    return scene_map_from_chess(load_chess_scene_json(path))


def exact_projections(camera: Camera, camera_from_world: np.ndarray,
                      ellipsoids: list[Ellipsoid]) -> list[tuple[Ellipse, Ellipsoid]]:
    """``(projection, ellipsoid)`` of every ellipsoid (world frame, m) whose projection at
    ``camera_from_world`` (4x4, OpenCV axes) is an ellipse (px), in the given order: the exact
    detections of a refinement problem (no image clipping)."""
    out = []
    for e in ellipsoids:
        try:
            out.append((project_ellipsoid(camera, camera_from_world, e), e))
        except DegenerateProjectionError:
            continue
    return out


def perturb_pose(
    world_from_camera: np.ndarray, rng: np.random.Generator, offset_m: float, angle_deg: float,
) -> np.ndarray:
    """A ``world_from_camera`` pose (4x4) moved away from ``world_from_camera``: the camera
    centre shifted by ``offset_m`` metres in a uniformly random direction (world frame) and the
    orientation rotated by ``angle_deg`` degrees about a uniformly random axis expressed in the
    CAMERA frame (right-multiplied: ``R' = R Exp(angle * axis)``).

    Draws, in order: the axis (3 normals), then the direction (3 normals). The one perturbation
    of the benches and tests (convergence experiments, refinement starts)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    a = np.radians(angle_deg)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    d = rng.normal(size=3)
    T = np.asarray(world_from_camera, dtype=float)
    return pose_matrix(T[:3, :3] @ R, T[:3, 3] + offset_m * d / np.linalg.norm(d))


def load_chess_world_from_camera(
    path: Path = CHESS_POSES_PATH,
) -> tuple[Camera, list[np.ndarray], list[str]]:
    """(camera, **world_from_camera** poses (4x4), frame names) of the 108 real test frames.

    Unlike :func:`tests.support.reference_data.load_chess_poses` (camera_from_world, the file's ``R,
    t`` with ``R`` snapped to the nearest rotation), this returns their inverses.
    """
    camera, camera_from_world, names = load_chess_poses(path)
    return camera, [invert_pose(T) for T in camera_from_world], names
