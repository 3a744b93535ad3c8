"""GTSAM factor of the level-set residual over ellipsoids (and optionally camera poses).

ONE factor type for everything that moves ellipsoids: the reconstruction of one object from
known views (``quadloc.maps.reconstruct``) and the joint refinement of a whole map, with or without
the camera poses (``quadloc.maps.building.joint``). The residual and its Jacobians are those of
:func:`quadloc.factors.ellipsoid_residuals.observation_residual` (the level-set residual of
localization, tested equal to :class:`quadloc.factors.pose_residuals.PoseResidualModel`).

A factor holds V observations (views). View ``v`` is a detection (its fixed samples, a row of a
:func:`quadloc.factors.ellipsoid_residuals.stack_samples` stack) of the ellipsoid in object slot
``view_objects[v]`` seen by the camera in camera slot ``view_cameras[v]`` (a refined ``Pose3``
key, ``world_from_camera``, OpenCV axes) or by a fixed camera (``camera_from_world[v]``).

Variables per object slot: ``(pose key, log-axes key)``: a ``Pose3`` (ellipsoid frame -> world,
translation = centre, m) and a ``Vector3`` of log semi-axes (log m). Keys of the factor, in
order: ``E_0, L_0, E_1, L_1, ..., X_0, X_1, ...``.

Rows (V * M, dimensionless, view-major): view ``v``'s residual times ``weights[v]`` (e.g.
``1 / sqrt(sigma)``, localization's whitening, ``quadloc.factors.pose_factors.make_noise_model``),
then, with ``robust_scale`` ``k``, scaled per view so that half its squared norm is Huber's cost of
the view's weighted residual norm (the Jacobian gets the same scale, as iteratively reweighted least
squares does; GTSAM's robust noise models reweight a whole factor, so a factor over many views
needs its kernel inside). A view that is not valid (:func:`valid_views`: its ellipsoid not
entirely in front of its camera, depth margin <= ``min_depth_margin`` m, or degenerate, a
semi-axis below ``MIN_AXIS_DEPTH_RATIO`` times its centre's depth) gives constant rows (total
cost ``penalty_cost * weight^2``, zero Jacobian): LM rejects steps that go there. The noise
model is unit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import gtsam
import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.camera import depth_margin
from quadloc.factors.ellipsoid_residuals import LevelSetSamples, observation_residual
from quadloc.factors.pose_residuals import DEFAULT_MIN_DEPTH_MARGIN
from quadloc.factors.rotations import invert_pose

__all__ = ["MIN_AXIS_DEPTH_RATIO", "PENALTY_COST", "depth_margins", "ellipsoid_views_factor",
           "huber_row_scale", "valid_views"]

#: Cost of one invalid view (:func:`valid_views`), before the view's weight.
PENALTY_COST = 1e6
#: Smallest semi-axis of a valid view's ellipsoid, as a fraction of its centre's depth in the
#: camera. Below it the projected conic ``A = S_c - c_c c_c^T`` (``S_c`` the shape matrix and
#: ``c_c`` the centre in the camera frame) is the point's ``-c_c c_c^T`` up to rounding: the
#: ellipsoid's part, of eigenvalues ``~ axis^2``, is lost in the ``~1e-16 |c_c|^2`` rounding of
#: the point's, and ``A`` is singular in floating point (an LM trial step that collapses the log
#: semi-axes, e.g. to ``[-36, -318, -126]``, did that). At ``1e-6`` ``A``'s smallest eigenvalue
#: is still ~1e4 times that rounding; no object is that thin (1 micron at 1 m).
MIN_AXIS_DEPTH_RATIO = 1e-6


def huber_row_scale(norms: FloatArray, k: float) -> FloatArray:
    """Row scale (same shape as ``norms``) so that ``0.5 (scale |w|)^2`` is Huber's cost of
    ``|w|`` with threshold ``k``: 1 inside, ``sqrt(2 k (|w| - k / 2)) / |w|`` outside."""
    norms = np.asarray(norms, dtype=float)
    out = np.ones_like(norms)
    big = norms > k
    out[big] = np.sqrt(2.0 * k * (norms[big] - 0.5 * k)) / norms[big]
    return out


def depth_margins(camera_from_world: FloatArray, rotation: FloatArray, center: FloatArray,
                  axes: FloatArray) -> FloatArray:
    """Smallest depth (m) of the ellipsoid in each camera (batched like
    :func:`quadloc.factors.ellipsoid_residuals.observation_residual`): ``d . c + t_z - sqrt(d^T S
    d)`` with ``d`` the camera's optical axis in the world (third row of ``R_cw``) and ``S`` the
    shape matrix ``R diag(axes^2) R^T`` (the formula:
    :func:`quadloc.factors.camera.depth_margin`)."""
    R = np.asarray(rotation, dtype=float)
    S = (R * (np.asarray(axes, dtype=float) ** 2)[..., None, :]) @ np.swapaxes(R, -1, -2)
    d = camera_from_world[..., 2, :3]
    spread = np.einsum("...i,...ij,...j->...", d, S, d)
    return depth_margin(np.einsum("...i,...i->...", d, center) + camera_from_world[..., 2, 3],
                        spread)


def valid_views(camera_from_world: FloatArray, rotation: FloatArray, center: FloatArray,
                axes: FloatArray, min_depth_margin: float = DEFAULT_MIN_DEPTH_MARGIN) -> BoolArray:
    """Views (batched like :func:`depth_margins`) whose residual
    :func:`quadloc.factors.ellipsoid_residuals.observation_residual` is defined: the ellipsoid
    is entirely in front of the camera (depth margin > ``min_depth_margin`` m) and every
    semi-axis is at least ``MIN_AXIS_DEPTH_RATIO`` times the depth of its centre (the projected
    conic is not singular in floating point). False for non-finite poses or shapes."""
    T = np.asarray(camera_from_world, dtype=float)
    depth = np.einsum("...i,...i->...", T[..., 2, :3], np.asarray(center, dtype=float)) \
        + T[..., 2, 3]
    smallest = np.min(np.asarray(axes, dtype=float), axis=-1)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite shapes: NaN, invalid
        in_front = depth_margins(T, rotation, center, axes) > min_depth_margin
    ok: BoolArray = in_front & (smallest >= MIN_AXIS_DEPTH_RATIO * depth)
    return ok


def ellipsoid_views_factor(
    samples: LevelSetSamples, weights: FloatArray,
    object_keys: Sequence[tuple[int, int]], view_objects: Sequence[int] | IntArray, *,
    camera_keys: Sequence[int] = (), view_cameras: Sequence[int] | IntArray | None = None,
    camera_from_world: FloatArray | None = None, robust_scale: float | None = None,
    penalty_cost: float = PENALTY_COST, min_depth_margin: float = DEFAULT_MIN_DEPTH_MARGIN,
    on_evaluate: Callable[[], None] | None = None,
) -> gtsam.CustomFactor:
    """The factor of the module docstring.

    Args:
        samples: the V detections' samples stacked (``n`` (V, 3, M), ``phi_det_minus_1`` (V, M)).
        weights: (V,) row scale of each view (1 / std of its residual).
        object_keys: ``(Pose3 key, log-axes key)`` per object slot.
        view_objects: (V,) object slot of each view.
        camera_keys: ``Pose3`` keys (``world_from_camera``) of refined cameras; empty for fixed
            cameras.
        view_cameras: (V,) camera slot of each view (with ``camera_keys``).
        camera_from_world: (V, 4, 4) fixed cameras (without ``camera_keys``). Its top 3x4
            may also be a projection ``K [R|t]`` (``K``'s last row ``(0, 0, 1)``) when the
            samples' rays are in homogeneous pixels (``K n``): the residual, the ellipsoid
            Jacobians and the depth margin are unchanged by that change of image coordinates
            (``quadloc.maps.reconstruct`` samples the observed contour in pixels this way).
        robust_scale: Huber threshold on each view's weighted residual norm; None: quadratic.
        penalty_cost, min_depth_margin: see the module docstring.
        on_evaluate: called at every evaluation (progress reporting).
    """
    n = np.asarray(samples.n, dtype=float)
    phi = np.asarray(samples.phi_det_minus_1, dtype=float)
    V, M = phi.shape
    w = np.asarray(weights, dtype=float).reshape(V)
    obj = np.asarray(view_objects, dtype=int).reshape(V)
    n_obj = len(object_keys)
    if obj.min(initial=0) < 0 or obj.max(initial=0) >= n_obj:
        raise ValueError("view_objects must index object_keys")
    cam_keys = list(camera_keys)
    if cam_keys:
        if view_cameras is None:
            raise ValueError("view_cameras is required with camera_keys")
        cam = np.asarray(view_cameras, dtype=int).reshape(V)
        if cam.min(initial=0) < 0 or cam.max(initial=0) >= len(cam_keys):
            raise ValueError("view_cameras must index camera_keys")
        fixed = None
    else:
        if camera_from_world is None or np.shape(camera_from_world) != (V, 4, 4):
            raise ValueError("give camera_keys or camera_from_world (V, 4, 4)")
        cam = None
        fixed = np.array(camera_from_world, dtype=float)
    pen = np.sqrt(2.0 * penalty_cost / M) * np.abs(w)
    obj_sel = None if n_obj == 1 else [obj == s for s in range(n_obj)]
    cam_sel = None if cam is None or len(cam_keys) == 1 else [cam == s for s in
                                                               range(len(cam_keys))]
    keys = [k for pair in object_keys for k in pair] + cam_keys
    noise = gtsam.noiseModel.Unit.Create(V * M)
    all_samples = LevelSetSamples(None, n, phi)

    def blocks(J: FloatArray, sel: list[BoolArray] | None, count: int) -> list[FloatArray]:
        """Per-slot Jacobian blocks (V * M, d): rows of other slots' views are zero."""
        d = J.shape[-1]
        if sel is None:
            return [np.ascontiguousarray(J.reshape(V * M, d))]
        out = []
        for s in range(count):
            B = np.zeros((V, M, d))
            B[sel[s]] = J[sel[s]]
            out.append(B.reshape(V * M, d))
        return out

    def error_fn(this: gtsam.CustomFactor, values: gtsam.Values,
                 H: gtsam.JacobianVector | None) -> FloatArray:
        if on_evaluate is not None:
            on_evaluate()
        Rs = np.empty((n_obj, 3, 3))
        cs = np.empty((n_obj, 3))
        la = np.empty((n_obj, 3))
        for s, (ek, lk) in enumerate(object_keys):
            pose = values.atPose3(ek)
            Rs[s] = pose.rotation().matrix()
            cs[s] = pose.translation()
            la[s] = values.atVector(lk)
        axes_s = np.exp(la)
        if n_obj == 1:
            R, c, axes = Rs[0], cs[0], axes_s[0]
        else:
            R, c, axes = Rs[obj], cs[obj], axes_s[obj]
        if fixed is not None:
            T_cw = fixed
        else:
            T_cw = invert_pose(np.array([values.atPose3(x).matrix() for x in cam_keys]))[cam]
        ok = valid_views(T_cw, R, c, axes, min_depth_margin)
        want = H is not None
        out = np.empty((V, M))
        out[~ok] = pen[~ok, None]
        J_e = np.zeros((V, M, 9)) if want else None
        J_c = np.zeros((V, M, 6)) if want and cam is not None else None
        if ok.any():
            if ok.all():
                sub, Rv, cv, av, T = all_samples, R, c, axes, T_cw
            else:
                sub = LevelSetSamples(None, n[ok], phi[ok])
                Rv, cv, av = ((R, c, axes) if n_obj == 1 else (R[ok], c[ok], axes[ok]))
                T = T_cw[ok]
            r, Je, Jc = observation_residual(T, Rv, cv, av, sub, want)
            scale = w[ok]
            if robust_scale is not None:
                scale = scale * huber_row_scale(np.abs(scale) * np.sqrt((r * r).sum(axis=1)),
                                                robust_scale)
            out[ok] = r * scale[:, None]
            if J_e is not None and Je is not None:
                J_e[ok] = Je * scale[:, None, None]
                if J_c is not None and Jc is not None:
                    J_c[ok] = Jc * scale[:, None, None]
        if H is not None and J_e is not None:
            Hs = [np.ascontiguousarray(B[:, part]) for B in blocks(J_e, obj_sel, n_obj)
                  for part in (slice(0, 6), slice(6, 9))]  # pose, log-axes of each object
            if J_c is not None:  # cameras refined
                Hs += blocks(J_c, cam_sel, len(cam_keys))
            for i, B in enumerate(Hs):
                H[i] = B
        return out.reshape(-1)

    return gtsam.CustomFactor(noise, keys, error_fn)

