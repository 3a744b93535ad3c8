"""Synthetic scenes of the tests and benchmarks: a test camera, ``look_at`` poses, two-ellipsoid
scenes for P2E, large synthetic maps, the frames in which an ellipsoid is visible, and whether two
ellipsoids intersect.

Poses are ``world_from_camera`` (4x4, OpenCV camera axes) unless named otherwise; +Z is up.
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid, ellipsoid_depth_margins, project_ellipsoid
from quadloc.factors.conics import DegenerateProjectionError
from quadloc.factors.rotations import invert_pose, pose_matrix, snap_to_rotation
from quadloc.maps.model import MapObject, SceneMap

__all__ = ["CAM", "UP", "ellipsoids_intersect", "look_at", "random_pair_scene", "synthetic_map",
           "visible_frames"]


def synthetic_map(n_objects: int, seed: int, n_categories: int = 8) -> SceneMap:
    """``n_objects`` ellipsoids (semi-axes 0.1-0.5 m, random yaw) on a floor of side
    ``2 sqrt(n)`` m (one object per 4 m^2), heights 0-2 m, ``n_categories`` labels; +Z up."""
    rng = np.random.default_rng(seed)
    side = 2.0 * math.sqrt(n_objects)
    cats = tuple(f"c{k}" for k in range(n_categories))
    objs = []
    for k in range(n_objects):
        yaw = rng.uniform(-math.pi, math.pi)
        R = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                      [0, 0, 1]])
        e = Ellipsoid(np.array([rng.uniform(0, side), rng.uniform(0, side),
                                rng.uniform(0.1, 2.0)]), rng.uniform(0.1, 0.5, 3), R)
        objs.append(MapObject(f"o{k}", cats[k % n_categories], e))
    return SceneMap(f"synthetic-{n_objects}", f"synthetic {n_objects}", (0.0, 0.0, 1.0), cats,
                    tuple(objs))


def ellipsoids_intersect(a: Ellipsoid, b: Ellipsoid) -> bool:
    """True if the solid ellipsoids ``a`` and ``b`` share a point (touching counts).

    The exact test of Gilitschenski and Hanebeck ("A robust computational test for overlap of
    two arbitrary-dimensional ellipsoids in fault-detection of Kalman filters", FUSION 2012):
    with shape matrices ``A = R diag(axes^2) R^T`` (m^2) and ``d = b.center - a.center`` (m),
    the ellipsoids intersect iff ``K(s) = 1 - d^T (A / (1 - s) + B / s)^-1 d >= 0`` for every
    ``s`` in (0, 1) (``K`` is convex in ``s``). After whitening ``a`` to the unit sphere
    (``B' = L B L^T = Q diag(lam) Q^T``, ``d' = L d``, ``L = A^-1/2``),
    ``K(s) = 1 - sum_i (Q^T d')_i^2 s (1 - s) / (s + lam_i (1 - s))``; its minimum is found on
    a grid of ``s`` refined by golden-section search.
    """
    d = b.center - a.center
    if float(np.linalg.norm(d)) > float(a.axes.max() + b.axes.max()):
        return False  # the bounding spheres are apart
    whiten = np.diag(1.0 / a.axes) @ a.rotation.T  # L: a -> the unit sphere
    shape_b = whiten @ b.shape_matrix() @ whiten.T
    lam, Q = np.linalg.eigh(shape_b)
    c = (Q.T @ (whiten @ d)) ** 2

    def k(s: np.ndarray) -> np.ndarray:
        s = s[:, None]
        return 1.0 - np.sum(c * s * (1.0 - s) / (s + lam * (1.0 - s)), axis=1)

    grid = np.linspace(0.0, 1.0, 65)[1:-1]
    i = int(np.argmin(k(grid)))
    lo, hi = grid[i - 1] if i else 0.0, grid[i + 1] if i + 1 < len(grid) else 1.0
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):  # bracket shrinks by 0.618 per step: below 1e-13 of (0, 1)
        m1, m2 = hi - golden * (hi - lo), lo + golden * (hi - lo)
        if k(np.array([m1]))[0] <= k(np.array([m2]))[0]:
            hi = m2
        else:
            lo = m1
    return bool(k(np.array([(lo + hi) / 2.0]))[0] >= 0.0)


CAM = Camera(500.0, 520.0, 320.0, 240.0, 640, 480)


UP = np.array([0.0, 0.0, 1.0])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = UP,
            roll: float = 0.0) -> np.ndarray:
    """world_from_camera of a camera at ``eye`` looking at ``target`` with +X horizontal
    (zero roll) then rolled by ``roll`` radians about its optical axis."""
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    c, s = math.cos(roll), math.sin(roll)
    R = np.column_stack([x, np.cross(z, x), z]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return pose_matrix(R, eye)


def random_pair_scene(rng: np.random.Generator, axes_range: tuple[float, float] = (0.1, 0.4),
                      roll: float = 0.0):
    """(ellipsoids, exact ellipses, camera_from_world) of a camera ~4 m from two random
    ellipsoids (semi-axes in ``axes_range`` m), looking near their midpoint, rolled by ``roll``
    radians about its optical axis (also the tests' scene generator)."""
    while True:
        E = [Ellipsoid(rng.uniform(-1, 1, 3), rng.uniform(*axes_range, 3),
                       snap_to_rotation(rng.normal(size=(3, 3)))) for _ in range(2)]
        eye = rng.uniform(-1, 1, 3) + np.array([0.0, -4.0, 0.5])
        T_cw = invert_pose(look_at(eye, (E[0].center + E[1].center) / 2
                                   + rng.normal(0, 0.2, 3), roll=roll))
        try:
            return E, [project_ellipsoid(CAM, T_cw, e) for e in E], T_cw
        except DegenerateProjectionError:
            continue


def visible_frames(cam: Camera, cfw: list[np.ndarray], ellipsoid: Ellipsoid) -> list[int]:
    """Frames where ``ellipsoid`` is entirely in front and its image centre is in the image."""
    out = []
    for i, T in enumerate(cfw):
        margin = ellipsoid_depth_margins(T, ellipsoid.center[None],
                                         ellipsoid.shape_matrix()[None])[0]
        if margin <= 0:
            continue
        e = project_ellipsoid(cam, T, ellipsoid)
        if 0 <= e.cx < cam.width and 0 <= e.cy < cam.height:
            out.append(i)
    return out
