"""The level-set residuals of all pairs as functions of the camera pose, with analytic
Jacobians (one compiled kernel), and the layout of their fixed samples.

``r = Phi_det(x) - Phi_proj(x) = (Phi_det(x) - 1) + s n^T A^-1 n`` (dimensionless, ``Phi``
units) at the detection's samples ``x`` (px; rays ``n = K^-1 (x, y, 1)``, ``s = A[2,2]``, ``A``
of :mod:`quadloc.factors.pose_frame`), fixed at the initial pose: the layout of
``quadloc.factors.metrics.level_set_sample_points`` (tested equal), grown for the misalignment
at that pose when the sampling is adaptive, except for a detection touching the image border
(:func:`quadloc.factors.camera.border_touching`: its layout is the metric's with
``adaptive=False``). Residuals (N, M) and Jacobians (N, M, 6) w.r.t. the pose tangent of
:mod:`quadloc.factors.pose_frame`. Derivation and measurements: ``docs/design/factors.md``
("Pose residuals", level-set residual; "Truncated detections").
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np

from quadloc.factors import camera as _camera
from quadloc.factors import metrics
from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.jit import jit
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows

__all__ = ["LevelSetResiduals"]


@jit
def _level_set_kernel(
    T: FloatArray, centers: FloatArray, S_world: FloatArray, S_world_inv: FloatArray,
    rays: FloatArray, phi0: FloatArray, min_depth_margin: float,
) -> FloatArray:
    """Level-set Jacobians (N, M, 6) and residuals (N, M) of all pairs at ``T``
    (``world_from_camera`` 4x4), per object its depth margin (N,) m
    (:func:`quadloc.factors.camera.depth_margin`'s compiled form, of its centre's depth ``z_c``
    and ``S_c[2, 2]``; the rows of a pair whose margin is ``<= min_depth_margin`` m are garbage,
    replaced by the penalty), then the number of such pairs and the sum of all squared residuals,
    in ONE flat array of ``7 N M + N + 2`` values in that order (:func:`_split`: returning one
    array instead of several saves ~2.5 us of boxing per call; the margins, the validity count
    and the sum here instead of numpy calls on small arrays save ~5 us per evaluation). Docs:
    docs/design/factors.md, "Level-set residual".

    Per object, ``A^-1`` by Sherman-Morrison from the world frame, ``A_w = S_w - d d^T`` (``d``
    the centre seen from the camera, world axes): ``A_w^-1 = S_w^-1 + e e^T / (1 - d . e)``,
    ``e = S_w^-1 d``, ``A^-1 = R^T A_w^-1 R``; then per sample ray ``n`` (``rays`` (N, 3, M)),
    with ``u = A^-1 n``, ``g = n . u``, ``s = A[2, 2]``::

        r      = phi0 + s g                       (phi0 = Phi_det(x) - 1, (N, M))
        dr/dw  = 2 g (e3 x A e3) + 2 s (n x u)
        dr/dv  = 2 g z_c e3 - 2 (s A^-1 c_c . n) u
    """
    n_obj, m = phi0.shape
    out = np.empty(7 * n_obj * m + n_obj + 2)
    J = out[:6 * n_obj * m].reshape((n_obj, m, 6))
    r = out[6 * n_obj * m:7 * n_obj * m].reshape((n_obj, m))
    margins = out[7 * n_obj * m:7 * n_obj * m + n_obj]
    n_invalid = 0
    sum_sq = 0.0
    Ai_w = np.empty((3, 3))
    Ai = np.empty((3, 3))
    for j in range(n_obj):
        d0, d1, d2 = centers[j, 0] - T[0, 3], centers[j, 1] - T[1, 3], centers[j, 2] - T[2, 3]
        z = d0 * T[0, 2] + d1 * T[1, 2] + d2 * T[2, 2]
        # S_w R e3, and A e3 = R^T (S_w R e3 - d z) in camera axes
        w0 = S_world[j, 0, 0] * T[0, 2] + S_world[j, 0, 1] * T[1, 2] + S_world[j, 0, 2] * T[2, 2]
        w1 = S_world[j, 1, 0] * T[0, 2] + S_world[j, 1, 1] * T[1, 2] + S_world[j, 1, 2] * T[2, 2]
        w2 = S_world[j, 2, 0] * T[0, 2] + S_world[j, 2, 1] * T[1, 2] + S_world[j, 2, 2] * T[2, 2]
        margins[j] = _camera.depth_margin_kernel(z, w0 * T[0, 2] + w1 * T[1, 2] + w2 * T[2, 2])
        if not margins[j] > min_depth_margin:
            n_invalid += 1
        w0, w1, w2 = w0 - d0 * z, w1 - d1 * z, w2 - d2 * z
        a0 = T[0, 0] * w0 + T[1, 0] * w1 + T[2, 0] * w2
        a1 = T[0, 1] * w0 + T[1, 1] * w1 + T[2, 1] * w2
        s = T[0, 2] * w0 + T[1, 2] * w1 + T[2, 2] * w2
        # e = S_w^-1 d, A_w^-1 = S_w^-1 + e e^T / den
        e0 = S_world_inv[j, 0, 0] * d0 + S_world_inv[j, 0, 1] * d1 + S_world_inv[j, 0, 2] * d2
        e1 = S_world_inv[j, 1, 0] * d0 + S_world_inv[j, 1, 1] * d1 + S_world_inv[j, 1, 2] * d2
        e2 = S_world_inv[j, 2, 0] * d0 + S_world_inv[j, 2, 1] * d1 + S_world_inv[j, 2, 2] * d2
        den = 1.0 - (d0 * e0 + d1 * e1 + d2 * e2)
        e0, e1, e2 = e0 / den, e1 / den, e2 / den  # now A_w^-1 d; e e^T / den = den e' e'^T
        for a in range(3):
            ea = e0 if a == 0 else (e1 if a == 1 else e2)
            for b in range(3):
                eb = e0 if b == 0 else (e1 if b == 1 else e2)
                Ai_w[a, b] = S_world_inv[j, a, b] + ea * eb * den
        # A^-1 = R^T A_w^-1 R
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for p in range(3):
                    for q in range(3):
                        acc += T[p, a] * Ai_w[p, q] * T[q, b]
                Ai[a, b] = acc
        # s A^-1 c_c = s R^T A_w^-1 d
        sw0 = s * (T[0, 0] * e0 + T[1, 0] * e1 + T[2, 0] * e2)
        sw1 = s * (T[0, 1] * e0 + T[1, 1] * e1 + T[2, 1] * e2)
        sw2 = s * (T[0, 2] * e0 + T[1, 2] * e1 + T[2, 2] * e2)
        for i in range(m):
            n0, n1, n2 = rays[j, 0, i], rays[j, 1, i], rays[j, 2, i]
            u0 = Ai[0, 0] * n0 + Ai[0, 1] * n1 + Ai[0, 2] * n2
            u1 = Ai[1, 0] * n0 + Ai[1, 1] * n1 + Ai[1, 2] * n2
            u2 = Ai[2, 0] * n0 + Ai[2, 1] * n1 + Ai[2, 2] * n2
            g = n0 * u0 + n1 * u1 + n2 * u2
            p = sw0 * n0 + sw1 * n1 + sw2 * n2
            r_ji = phi0[j, i] + s * g
            r[j, i] = r_ji
            sum_sq += r_ji * r_ji
            # (n x u) = -(u x n)
            J[j, i, 0] = -2.0 * a1 * g - 2.0 * s * (u1 * n2 - u2 * n1)
            J[j, i, 1] = 2.0 * a0 * g - 2.0 * s * (u2 * n0 - u0 * n2)
            J[j, i, 2] = -2.0 * s * (u0 * n1 - u1 * n0)
            J[j, i, 3] = -2.0 * p * u0
            J[j, i, 4] = -2.0 * p * u1
            J[j, i, 5] = -2.0 * p * u2 + 2.0 * z * g
    out[7 * n_obj * m + n_obj] = n_invalid
    out[7 * n_obj * m + n_obj + 1] = sum_sq
    return out


def _split(out: FloatArray, n: int, m: int
           ) -> tuple[FloatArray, FloatArray, FloatArray, int, float]:
    """The residuals (N, M), Jacobians (N, M, 6), depth margins (N,), the number of invalid
    pairs and the sum of squared residuals: views and values of :func:`_level_set_kernel`'s
    flat result."""
    nm6, nm7 = 6 * n * m, 7 * n * m
    return (out[nm6:nm7].reshape(n, m), out[:nm6].reshape(n, m, 6), out[nm7:nm7 + n],
            int(out[nm7 + n]), float(out[nm7 + n + 1]))


@functools.lru_cache(maxsize=32)
def _unit_level_set_layout(n_azimuths: int, n_levels: int) -> tuple[FloatArray, FloatArray]:
    """``quadloc.factors.metrics``' level-set layout for a unit circle, s_max = 1: the homogeneous
    points ``(u, v, 1)`` as columns (3, M) and ``u^2 + v^2`` (1, M), read-only."""
    uv = metrics.level_set_sample_points(Ellipse(0.0, 0.0, 1.0, 1.0, 0.0), None,
                                         n_azimuths=n_azimuths, n_levels=n_levels, scale=1.0,
                                         adaptive=False)
    uv1 = np.ones((3, len(uv)))
    uv1[:2] = uv.T
    uv2: FloatArray = (uv * uv).sum(axis=1)[None, :]
    for arr in (uv1, uv2):
        arr.setflags(write=False)
    return uv1, uv2


class LevelSetResiduals:
    """Level-set residuals of N detection/ellipsoid pairs (:class:`PoseResidualFamily
    <quadloc.factors.pose_frame.PoseResidualFamily>`), ``dim = M`` samples per pair.

    ``detection_params`` (N, 5) px / rad; ``options`` the metric's (``n_azimuths``,
    ``n_levels``, ``scale``, ``adaptive``; validated here); the samples are laid out at
    ``initial_world_from_camera`` (4x4, or None: not grown) and again by :meth:`lay_out`.
    """

    def __init__(
        self, detection_params: FloatArray, ellipsoids: EllipsoidArrays, camera: Camera,
        options: Mapping[str, object], min_depth_margin: float,
        initial_world_from_camera: FloatArray | None,
    ) -> None:
        self._ellipsoids = ellipsoids
        self._camera = camera
        self._min_depth_margin = min_depth_margin
        # world-frame shape matrix S_w = L L^T and its inverse R diag(axes^-2) R^T
        L, rot, axes = ellipsoids.shape_factors, ellipsoids.rotations, ellipsoids.axes
        self._S_world: FloatArray = L @ L.transpose(0, 2, 1)
        self._S_world_inv: FloatArray = (rot / (axes * axes)[:, None, :]) @ rot.transpose(0, 2, 1)
        #: residual components (samples) per pair
        self.dim = int(metrics.residual_size("level_set", **options))  # validates options
        self._scale = metrics._positive_float(  # validated as by the metric
            "scale", options.get("scale", metrics.DEFAULT_LEVEL_SET_SCALE))
        self._adaptive = bool(options.get("adaptive", True))
        self._uv1, self._uv2 = _unit_level_set_layout(
            metrics._positive_int("n_azimuths", options.get("n_azimuths", 6)),
            metrics._positive_int("n_levels", options.get("n_levels", 4)))
        # canonical axes a >= b (the metric's layout does not depend on axis labelling)
        axes_angle = metrics.canonical_axes(detection_params)
        ca, sa = np.cos(axes_angle[:, 2]), np.sin(axes_angle[:, 2])
        focal = np.array([camera.fx, camera.fy])
        n = len(detection_params)
        # H without s_max: columns 0, 1 (R(angle) diag(a, b) over the focal lengths) scale
        # with s_max, column 2 is K^-1 (c_D, 1)
        H = np.zeros((n, 3, 3))
        H[:, :2, :2] = (np.stack((ca, -sa, sa, ca), axis=1).reshape(n, 2, 2)
                        * axes_angle[:, None, :2] / focal[:, None])
        H[:, :2, 2] = (detection_params[:, :2] - (camera.cx, camera.cy)) / focal
        H[:, 2, 2] = 1.0
        self._H = H
        self._H_inv = np.linalg.inv(H)
        self._detection_params = detection_params
        self._truncated: BoolArray | None = None  # computed when first needed (truncated)
        #: (N,) all True, read-only: :meth:`rows`' validity when every margin is above the minimum
        self._all_valid: BoolArray = np.ones(n, dtype=bool)
        self._all_valid.setflags(write=False)
        self.lay_out(initial_world_from_camera)

    def lay_out(self, world_from_camera: FloatArray | None) -> None:
        """Fix the samples: ``quadloc.factors.metrics.level_set_sample_points``' layout for all
        detections at once, grown (if adaptive) for the misalignment at ``world_from_camera``
        (4x4; None: not grown), except a detection touching the image border
        (:attr:`truncated`).

        Sample ``m`` of detection ``j`` is the affine image ``x = c_D + R_D diag(a, b) s_max
        (u_m, v_m)`` of the unit layout ``(u_m, v_m)``, so its normalised ray ``n = K^-1 (x,
        y, 1) = H_j (u_m, v_m, 1)`` with a per-object 3x3 ``H_j``: one matmul lays out all."""
        scale, n = self._scale, len(self._H)
        if self._adaptive and world_from_camera is not None:
            frame = self._ellipsoids.camera_frame(world_from_camera)
            a3 = frame.A[:, :, 2]  # A e3, camera axes
            ok = frame.depth_margins > self._min_depth_margin
            # The projected centre c_P is the point of C* e3 = K A K^T e3 = K A e3, so its ray is
            # n = A e3 / s, and H^-1 n = (u, v, 1) are its coordinates in the detection's
            # axes over its semi-axes: Phi_D(c_P) = u^2 + v^2 = |(H^-1 A e3)[:2]|^2 / s^2
            # (quadloc.factors.conics.level_values; the same layout as quadloc.factors.metrics,
            # tested).
            p = (self._H_inv @ a3[:, :, None])[:, :, 0]
            all_ok = bool(ok.all())  # the usual case: no masking
            w = p[:, 2] if all_ok else np.where(ok, p[:, 2], 1.0)
            phi = (p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1]) / (w * w)
            s_max = np.maximum(scale, metrics.LEVEL_SET_ADAPTIVE_GAIN * np.sqrt(phi))
            if not all_ok:
                s_max = np.where(ok, s_max, scale)
            if (s_max > scale).any():  # rare (a start far off): only then the border rule
                s_max = np.where(self.truncated, scale, s_max)
        else:
            s_max = np.full(n, scale)
        #: (N,) outermost level radius per detection (in detection radii)
        self.sampling_scale: FloatArray = s_max
        #: some detection's sampled area was grown for the misalignment
        self.sampling_grown = bool((s_max > scale).any())
        self._phi0: FloatArray = self._uv2 * (s_max**2)[:, None] - 1.0
        Hs = self._H.copy()
        Hs[:, :, :2] *= s_max[:, None, None]
        self._rays: FloatArray = Hs @ self._uv1  # (N, 3, M) normalised camera coordinates

    @property
    def truncated(self) -> BoolArray:
        """(N,) bool: detection ``j`` touches the image border
        (:func:`quadloc.factors.camera.border_touching`), so it is probably truncated: its
        ellipse is that of the visible part, whose centre differs from the projection's even
        at the true pose, so :meth:`lay_out` does not grow its samples for that "misalignment"
        (grown, its sampled area reached up to 1.9e9 detection radii, and the residuals far
        out, where the detected and the projected level sets differ most, pulled the pose
        metres off: docs/design/factors.md, "Truncated detections")."""
        if self._truncated is None:
            self._truncated = _camera.border_touching(self._detection_params, self._camera)
            self._truncated.setflags(write=False)
        return self._truncated

    @property
    def sample_points(self) -> FloatArray:
        """The fixed sample points (N, M, 2), pixels (``K n``)."""
        cam, rays = self._camera, self._rays
        return np.stack([cam.fx * rays[:, 0] + cam.cx, cam.fy * rays[:, 1] + cam.cy], axis=-1)

    def rows(self, world_from_camera: FloatArray, jacobian: bool) -> PairRows:
        """Residuals (N, M) and Jacobians (N, M, 6) of all pairs (:func:`_level_set_kernel`; the
        Jacobian is always computed with the residual, whatever ``jacobian``)."""
        # a fresh C-ordered copy of the pose: the kernels are compiled for that one type
        phi0 = self._phi0
        out = _level_set_kernel(np.array(world_from_camera, float, order="C"),
                                self._ellipsoids.centers, self._S_world, self._S_world_inv,
                                self._rays, phi0, self._min_depth_margin)
        n, m = phi0.shape
        if out[7 * n * m + n] == 0.0:
            # the usual case, every pair valid: no comparison, the residuals' sum of squares
            # given, and every array read-only already (views of a read-only result)
            out.setflags(write=False)
            r, J, margins, _, sum_squares = _split(out, n, m)
            return PairRows(r, J, self._all_valid, margins, None, sum_squares)
        r, J, margins, _, _ = _split(out, n, m)
        return PairRows(r, J, margins > self._min_depth_margin, margins, None)
