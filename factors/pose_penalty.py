"""The barrier of the pose factors: a bounded penalty for invalid projections, and the
saturation that keeps every valid pair's cost below it.

Pure numpy, batched over the N pairs of one refinement (rows ``(N, dim)``, Jacobians
``(N, dim, 6)`` w.r.t. the pose tangent of :mod:`quadloc.factors.pose_frame`). Why these
constants and what they guarantee: ``docs/design/factors.md`` ("Pose residuals").

Penalty
-------
A projection is invalid when its depth margin ``m <= min_depth_margin`` (m, see
:mod:`quadloc.factors.pose_frame`). Its ``dim`` residual components then all equal
``sqrt(P_j / dim) * (1 + d / (d + d_s))``, ``d = min_depth_margin - m``, ``d_s`` the ellipsoid's
largest semi-axis (m): cost in ``[P_j, 4 P_j)``, Jacobian ``-sqrt(P_j/dim) d_s / (d + d_s)^2
dm/dxi`` (``dm/dw = e3 x c_c - (e3 x S_c e3) / sqrt(S_c[2,2])``, ``dm/dv = -e3``).

``P_j = penalty_cost * rho_j^2`` (:func:`penalty_costs`), ``rho_j`` the pair's reference
residual magnitude: ``L_j`` px for bbox / qbbox / wasserstein / algebraic / frobenius,
``max(1, s_max_j)^2`` for level_set (``s_max_j`` its sampling scale), 1 for iou / giou /
bhattacharyya; ``L_j = max(image diagonal, |c_D| + max(a_D, b_D))`` px.

Saturation
----------
The GTSAM factors see each VALID pair's residual saturated above half the penalty (``c =
||r||^2``, ``c_0 = P_j / 2``): ``h(c) = c`` for ``c <= c_0``, else ``c_0 + w (1 - exp(-(c -
c_0) / w))`` with ``w = 0.4 P_j`` (C^1, ``h < 0.9 P_j``), ``r_sat = r sqrt(h(c) / c)``; so every
valid cost is below every penalty.
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.metrics import METRIC_NAMES
from quadloc.factors.pose_frame import CameraFrame

__all__ = ["DepthMarginPenalty", "penalty_costs"]

#: Power of the reference length ``L_j`` (px) in the metric's residual: the penalty's
#: reference residual ``rho_j = L_j ** power`` (level_set: ``max(1, s_max_j)^2`` instead).
_PENALTY_PIXEL_POWER: dict[str, int] = {
    "iou": 0, "giou": 0, "bhattacharyya": 0, "level_set": 0, "bbox": 1, "qbbox": 1,
    "wasserstein": 1, "algebraic": 1, "frobenius": 1}
assert set(_PENALTY_PIXEL_POWER) == set(METRIC_NAMES)


def penalty_costs(metric: str, penalty_cost: float, detection_params: FloatArray,
                  camera: Camera, level_set_scale: FloatArray | None = None) -> FloatArray:
    """Per-pair penalty cost ``P_j = penalty_cost * rho_j^2`` (N,) (module docstring), from the
    detections' params (N, 5) (px, rad) and, for level_set, the sampling scales ``s_max_j``
    (N,)."""
    if metric == "level_set":
        if level_set_scale is None:
            raise ValueError("level_set penalty costs need the sampling scales")
        rho = np.maximum(1.0, level_set_scale) ** 2
    else:
        P = detection_params
        diag = math.hypot(camera.width, camera.height)
        L = np.maximum(diag, np.hypot(P[:, 0], P[:, 1]) + np.maximum(P[:, 2], P[:, 3]))
        rho = L ** _PENALTY_PIXEL_POWER[metric]
    costs: FloatArray = penalty_cost * rho * rho
    return costs


class DepthMarginPenalty:
    """The penalty rows of invalid pairs and the saturation of valid ones (module docstring),
    for pairs of ``dim`` residual components with penalty costs ``costs`` (N,) (made
    read-only), ellipsoids of largest semi-axes ``largest_semi_axes`` (N,) m, valid above
    ``min_depth_margin`` m."""

    def __init__(self, costs: FloatArray, largest_semi_axes: FloatArray, min_depth_margin: float,
                 dim: int) -> None:
        costs.setflags(write=False)
        #: ``P_j`` (N,), read-only
        self.costs = costs
        self._half = 0.5 * costs  # where the saturation starts
        self._floor = float(self._half.min())
        self._length_scales = largest_semi_axes
        self._min_depth_margin = min_depth_margin
        self._dim = dim

    def replace_invalid(self, residuals: FloatArray, jacobians: FloatArray | None,
                        invalid: BoolArray, frame: CameraFrame, depth_margins: FloatArray
                        ) -> None:
        """Overwrite rows ``invalid`` (N,) of ``residuals`` (N, dim) / ``jacobians`` (N, dim, 6)
        with the penalty, from the margins (N,) m and the frame's centres and shapes."""
        idx = np.flatnonzero(invalid)
        d = self._min_depth_margin - depth_margins[idx]
        ds = self._length_scales[idx]
        amp = np.sqrt(self.costs[idx] / self._dim)  # residual amplitude sqrt(P_j / dim)
        residuals[idx] = (amp * (1.0 + d / (d + ds)))[:, None]
        if jacobians is not None:
            cb = frame.centers[idx]
            s3 = frame.shapes[idx, :, 2]
            ext = np.sqrt(frame.shapes[idx, 2, 2])
            dm = np.zeros((idx.size, 6))
            dm[:, 0] = -cb[:, 1] + s3[:, 1] / ext
            dm[:, 1] = cb[:, 0] - s3[:, 0] / ext
            dm[:, 5] = -1.0
            coef = -amp * ds / (d + ds) ** 2
            jacobians[idx] = (coef[:, None] * dm)[:, None, :]

    def saturate(self, residuals: FloatArray, jacobians: FloatArray | None, valid: BoolArray,
                 sum_squares: float | None = None) -> tuple[FloatArray, FloatArray | None]:
        """The factors' residuals and Jacobians: the valid rows whose cost exceeds ``P_j / 2``
        saturated (module docstring). The SAME arrays when no row saturates (the usual case),
        new ones otherwise. ``sum_squares``: ``sum(residuals**2)`` if the caller has it."""
        r = residuals
        # fast path: the total cost is below every pair's c_0, so none can reach it
        if (float(np.vdot(r, r)) if sum_squares is None else sum_squares) <= self._floor:
            return r, jacobians
        c = (r * r).sum(axis=1)
        big = (c > self._half) & valid
        if not big.any():
            return r, jacobians
        P = self.costs
        c0 = self._half
        span = 0.4 * P  # h < c0 + span = 0.9 P
        e = np.exp(-np.where(big, c - c0, 0.0) / span)
        h = np.where(big, c0 + span * (1.0 - e), c)
        g = np.sqrt(h / np.where(big, c, 1.0))
        rs = np.where(big[:, None], r * g[:, None], r)
        J = jacobians
        if J is not None:
            # d g / d c = (h' c - h) / (2 c^2 g), h' = e; dc = 2 r^T dr
            dg = np.where(big, (e * c - h) / (2.0 * np.where(big, c, 1.0) ** 2 * g), 0.0)
            rJ = np.einsum("nm,nmk->nk", r, J)
            Js = J * g[:, None, None] + (2.0 * dg[:, None] * r)[:, :, None] * rJ[:, None, :]
            J = np.where(big[:, None, None], Js, J)
        return rs, J
