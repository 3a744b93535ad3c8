"""Helpers shared by the tests (one copy each), independent of the code under test.

* Ellipse/ellipsoid oracles written from their definitions (not used by production code):
  :func:`primal_conic`, :func:`ellipse_from_primal_conic`, :func:`level`, :func:`transformed`,
  :func:`surface_points`.
* Pose helpers: :func:`retract` (GTSAM's own retraction), :func:`angle_diff`.
* API helpers: :func:`assert_problem` (an RFC 9457 problem+json answer).
* :class:`FakeClock`: an injectable clock, so that tests advance time instead of sleeping;
  :class:`PerfCounterJump` for code that reads ``time.perf_counter`` deadlines.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np

from quadloc.factors.camera import Ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import rotation_from_quaternion_wxyz

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "FakeClock",
    "PerfCounterJump",
    "angle_diff",
    "assert_problem",
    "ellipse_from_primal_conic",
    "level",
    "primal_conic",
    "retract",
    "surface_points",
    "transformed",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"


# ----------------------------------------------------------------------------- ellipses


def primal_conic(e: Ellipse) -> np.ndarray:
    """Point conic ``C`` (3x3) of ``e``: ``x~^T C x~ = 0`` on the contour, ``< 0`` inside."""
    A = e.shape_matrix()
    c = e.center
    Ac = A @ c
    C = np.empty((3, 3))
    C[:2, :2] = A
    C[:2, 2] = -Ac
    C[2, :2] = -Ac
    C[2, 2] = c @ Ac - 1.0
    return C


def ellipse_from_primal_conic(conic: np.ndarray) -> Ellipse:
    """Ellipse of a point conic of any scale and sign (through its dual conic ``C^-1``)."""
    return Ellipse.from_dual_conic(np.linalg.inv(np.asarray(conic, dtype=float)))


def level(e: Ellipse, points: np.ndarray) -> np.ndarray:
    """``Phi(x) = (x - c)^T A (x - c)`` at ``points`` (..., 2) px; 1 on the contour."""
    d = np.asarray(points, dtype=float) - e.center
    return np.einsum("...i,ij,...j->...", d, e.shape_matrix(), d)


def transformed(e: Ellipse, angle: float, translation: Sequence[float]) -> Ellipse:
    """Image of ``e`` under ``x -> R(angle) x + translation`` (rotation about (0, 0))."""
    c, s = math.cos(angle), math.sin(angle)
    centre = np.array([[c, -s], [s, c]]) @ e.center + np.asarray(translation, dtype=float)
    return Ellipse(centre[0], centre[1], e.a, e.b, e.angle + angle)


def surface_points(E: Ellipsoid, n_azimuth: int = 32, n_polar: int = 16) -> np.ndarray:
    """Points on the surface of ``E`` (world metres), shape (n_azimuth * n_polar, 3)."""
    az = np.linspace(0, 2 * np.pi, n_azimuth, endpoint=False)
    po = np.linspace(0, np.pi, n_polar)
    A, P = np.meshgrid(az, po, indexing="ij")
    unit = np.stack([np.sin(P) * np.cos(A), np.sin(P) * np.sin(A), np.cos(P)], -1)
    return (unit.reshape(-1, 3) * E.axes) @ E.rotation.T + E.center


# ----------------------------------------------------------------------------- poses


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A random proper rotation (3, 3) (QR of a Gaussian matrix, determinant +1)."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def random_ellipsoids(rng: np.random.Generator, n: int, half_width_m: float,
                      half_height_m: float, semi_axes_m: tuple[float, float],
                      depth_m: tuple[float, float] = (3.0, 6.0)) -> list[Ellipsoid]:
    """``n`` ellipsoids in front of an identity camera (OpenCV axes, metres): centres uniform in
    ``|x| <= half_width_m``, ``|y| <= half_height_m``, ``z`` in ``depth_m``; semi-axes uniform
    in ``semi_axes_m``; orientations from uniform unit quaternions (wxyz, w >= 0)."""
    out = []
    for _ in range(n):
        q = rng.normal(size=4)
        q = q / np.linalg.norm(q) * np.sign(q[0])
        out.append(Ellipsoid(np.array([rng.uniform(-half_width_m, half_width_m),
                                       rng.uniform(-half_height_m, half_height_m),
                                       rng.uniform(*depth_m)]),
                             rng.uniform(*semi_axes_m, 3), rotation_from_quaternion_wxyz(q)))
    return out


def retract(T: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """``world_from_camera.retract(xi)`` computed by GTSAM (independent of our expmap)."""
    return gtsam.Pose3(T).retract(np.asarray(xi, dtype=float)).matrix()


def angle_diff(a: float, b: float) -> float:
    """Difference of two ellipse angles modulo the ellipse's 180-degree symmetry, radians."""
    return abs((a - b + math.pi / 2) % math.pi - math.pi / 2)


# ----------------------------------------------------------------------------- API


def assert_problem(r: Any, status: int, slug: str) -> dict:
    """Assert ``r`` is a problem+json answer with ``status`` and type ``urn:quadloc:problem:slug``
    carrying the standard members; return its body."""
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM_MEDIA_TYPE)
    body = r.json()
    assert body["type"] == f"urn:quadloc:problem:{slug}", body
    assert body["status"] == status
    assert set(body) >= {"type", "title", "status", "detail", "instance", "errors"}
    return body


def wait_for_job(client: Any, location: str, headers: dict[str, str] | None = None,
                 timeout_s: float = 120.0) -> dict[str, Any]:
    """Poll a build job's ``location`` with ``client`` (a TestClient or httpx client, sending
    ``headers``) until it has ended; its last body. Every read must be a 200: a job read never
    fails on stored data."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        r = client.get(location, headers=headers)
        assert r.status_code == 200, r.text
        job: dict[str, Any] = r.json()
        if job["status"] in ("succeeded", "failed"):
            return job
        time.sleep(0.1)
    raise AssertionError(f"job {location} did not end within {timeout_s} s")


# ----------------------------------------------------------------------------- time


class FakeClock:
    """A monotonic clock the test advances by hand: ``clock()`` -> seconds; ``advance(dt)``."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = float(start)

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += float(seconds)


class PerfCounterJump:
    """Patches ``time.perf_counter`` (for the test's duration) to the real counter plus an
    offset the test advances: a deadline is passed at once instead of by sleeping until it."""

    def __init__(self, monkeypatch: Any) -> None:
        self.offset = 0.0
        real = time.perf_counter
        monkeypatch.setattr(time, "perf_counter", lambda: real() + self.offset)

    def advance(self, seconds: float) -> None:
        self.offset += float(seconds)

    def past(self, deadline: float) -> None:
        """Jump just past ``deadline`` (a ``time.perf_counter()`` instant)."""
        self.advance(max(0.0, deadline - time.perf_counter()) + 1e-3)
