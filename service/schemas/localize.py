"""Wire models of localization: ``POST /v1/maps/{map_id}/localize`` and ``...:batch``; also the
shared request pieces (camera, detections, poses, priors, gravity) and answer pieces (poses,
covariances, inliers) of the other resources. Conventions: :mod:`quadloc.service.schemas.common`.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    model_validator,
)

from quadloc.factors.names import check_robust
from quadloc.service.limits import (
    AMBIGUITY_POLICIES,
    COVARIANCE_ORDER,
    GRAVITY_DEFAULT_SIGMA_DEG,
    GRAVITY_MAX_SIGMA_DEG,
    MAX_BATCH_FRAMES,
    MAX_DETECTIONS,
    MAX_PIXELS,
    METRICS,
    NO_REFINEMENT,
    POSE_SOURCES,
    ROBUST_KERNELS,
    UNKNOWN_LABEL_POLICIES,
)
from quadloc.service.schemas.common import (
    COVARIANCE_FRAME,
    Convention,
    Int,
    Row4,
    Row6,
    Text,
    WireModel,
    integral,
)

__all__ = [
    "ZONE_RULE",
    "AlternativeOut",
    "BatchLocalizeRequest",
    "BatchLocalizeResponse",
    "BoxIn",
    "CameraIn",
    "CovarianceOut",
    "DetectionIn",
    "EllipseIn",
    "GravityIn",
    "InlierOut",
    "LocalizeOptionsIn",
    "LocalizeRequest",
    "LocalizeResponse",
    "PoseIn",
    "PoseOut",
    "PosePriorIn",
]


class EllipseIn(WireModel):
    """Image ellipse: centre px, semi-axes px, angle radians (from +x towards +y)."""

    cx: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS, description="Centre x (px).")
    cy: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS, description="Centre y (px).")
    a: float = Field(gt=0, le=MAX_PIXELS, description="Semi-axis along `angle` (px).")
    b: float = Field(gt=0, le=MAX_PIXELS, description="Other semi-axis (px).")
    angle: float = Field(default=0.0, ge=-100.0, le=100.0,
                         description="Direction of semi-axis `a`, radians from +x towards +y.")

    @model_validator(mode="after")
    def _aspect(self) -> EllipseIn:
        if max(self.a, self.b) / min(self.a, self.b) > 1e4:
            raise ValueError("a/b aspect ratio must be <= 1e4 (degenerate ellipse)")
        return self


class BoxIn(WireModel):
    """Axis-aligned box in px; the detection becomes its inscribed ellipse."""

    xmin: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)
    ymin: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)
    xmax: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)
    ymax: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)

    @model_validator(mode="after")
    def _ordered(self) -> BoxIn:
        if not self.xmax > self.xmin:
            raise ValueError(f"xmax ({self.xmax}) must be > xmin ({self.xmin})")
        if not self.ymax > self.ymin:
            raise ValueError(f"ymax ({self.ymax}) must be > ymin ({self.ymin})")
        w, h = self.xmax - self.xmin, self.ymax - self.ymin
        if max(w, h) / min(w, h) > 1e4:
            raise ValueError("box aspect ratio must be <= 1e4 (degenerate box)")
        return self


class DetectionIn(WireModel):
    """One detected object: exactly one of `ellipse` or `box`, its label, optional uncertainty
    (`sigma` or `log_variance`, not both) and optional detector `score`."""

    ellipse: EllipseIn | None = None
    box: BoxIn | None = None
    label: Text = Field(min_length=1, max_length=128, description="Category label of the map.")
    sigma: float | None = Field(default=None, gt=0, le=1e6,
                                description="Predicted uncertainty (> 0); cost weight 1/sigma.")
    log_variance: float | None = Field(default=None, ge=-60, le=60,
                                       description="alpha = log sigma^2; sigma = exp(alpha/2).")
    score: float | None = Field(default=None, ge=0, le=1, description="Detector score.")

    @model_validator(mode="after")
    def _one_shape(self) -> DetectionIn:
        if (self.ellipse is None) == (self.box is None):
            raise ValueError("give exactly one of 'ellipse' or 'box'")
        if self.sigma is not None and self.log_variance is not None:
            raise ValueError("give at most one of 'sigma' or 'log_variance'")
        return self

    def effective_sigma(self) -> float | None:
        """``sigma``, or ``exp(log_variance / 2)``, or None."""
        if self.log_variance is not None:
            return math.exp(self.log_variance / 2.0)
        return self.sigma


class CameraIn(WireModel):
    """Pinhole intrinsics (px, zero skew, undistorted detections) and image size (px)."""

    fx: float = Field(gt=0, le=1e7)
    fy: float = Field(gt=0, le=1e7)
    cx: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)
    cy: float = Field(ge=-MAX_PIXELS, le=MAX_PIXELS)
    width: Int = Field(ge=1, le=100_000)
    height: Int = Field(ge=1, le=100_000)


class PoseIn(WireModel):
    """A ``world_from_camera`` pose: `quaternion_wxyz` (or `quaternion_xyzw`) + `translation_m`,
    or a 4x4 `matrix` given as a list of ROWS (row-major)."""

    quaternion_wxyz: list[float] | None = Field(
        default=None, min_length=4, max_length=4,
        description="Unit quaternion (w, x, y, z): |q| = 1 within 1e-6, else 422.")
    quaternion_xyzw: list[float] | None = Field(
        default=None, min_length=4, max_length=4,
        description="The same unit quaternion scalar LAST (ARKit/ARCore/Unity order); give "
                    "it instead of `quaternion_wxyz`.")
    translation_m: list[float] | None = Field(default=None, min_length=3, max_length=3)
    matrix: list[Row4] | None = Field(
        default=None, min_length=4, max_length=4,
        description="4x4 homogeneous matrix [[R, t], [0, 0, 0, 1]] given as a list of 4 ROWS "
                    "(row-major): R orthonormal within 1e-6 with det +1, last row [0, 0, 0, 1], "
                    "else 422.")

    @model_validator(mode="after")
    def _one_form(self) -> PoseIn:
        if self.quaternion_xyzw is not None:
            if self.quaternion_wxyz is not None:
                raise ValueError("give one of 'quaternion_wxyz' or 'quaternion_xyzw'")
            x, y, z, w = self.quaternion_xyzw
            self.quaternion_wxyz, self.quaternion_xyzw = [w, x, y, z], None
        has_q = self.quaternion_wxyz is not None or self.translation_m is not None
        if has_q == (self.matrix is not None):
            raise ValueError("give either 'quaternion_wxyz' + 'translation_m' or 'matrix'")
        if has_q and (self.quaternion_wxyz is None or self.translation_m is None):
            raise ValueError("'quaternion_wxyz' and 'translation_m' go together")
        for name in ("quaternion_wxyz", "translation_m", "matrix"):  # (matrix: 4x4 by type)
            v = getattr(self, name)
            rows = [v] if name != "matrix" else v
            if v is not None and any(abs(x) > 1e6 for row in rows for x in row):
                raise ValueError(f"'{name}' entries must be within +-1e6")
        return self


class PosePriorIn(WireModel):
    """Optional pose prior (e.g. from the AR session's tracking)."""

    world_from_camera: PoseIn
    covariance: list[Row6] | None = Field(
        default=None, min_length=6, max_length=6,
        description="Optional 6x6 covariance in GTSAM Pose3 tangent order [omega_x, omega_y, "
                    "omega_z, v_x, v_y, v_z], " + COVARIANCE_FRAME + ". Symmetric positive "
                    "definite. With it the prior is also a soft factor of the refinement.")
    convention: Convention = Field(default="opencv",
                                   description="Camera axes of this prior (opencv or opengl).")


class GravityIn(WireModel):
    """Optional gravity direction measured by the client (e.g. ARKit/ARCore/CoreMotion gravity):
    a factor on the pose's tilt (roll, pitch) in the refinement; candidates whose tilt
    disagrees with it are dropped, and an answer that disagrees is not localized (reason
    `gravity_mismatch`). The map's `up_axis` gives the world's up."""

    direction: list[float] = Field(
        min_length=3, max_length=3,
        description="Direction gravity pulls (DOWN, toward the ground) in the camera axes of "
                    "`convention`; any positive length. An accelerometer at rest measures the "
                    "opposite (up): negate it.")
    sigma_deg: float = Field(default=GRAVITY_DEFAULT_SIGMA_DEG, gt=0, le=GRAVITY_MAX_SIGMA_DEG,
                             description="Angular uncertainty (1 sigma per tilt axis, degrees).")
    convention: Convention = Field(default="opencv",
                                   description="Camera axes of `direction` (opencv or opengl).")

    @model_validator(mode="after")
    def _usable(self) -> GravityIn:
        if not all(math.isfinite(x) and abs(x) <= 1e6 for x in self.direction):
            raise ValueError("'direction' entries must be finite and within +-1e6")
        if math.hypot(*self.direction) <= 1e-9:
            raise ValueError("'direction' must not be the zero vector")
        return self


#: What a ``zone`` of an answer is (quadloc.maps.zones holds the rule).
ZONE_RULE = ("The map zone (docs/maps.md) holding the most of this pose's inlier objects; ties: "
             "the zone with the fewest objects (a room before its floor), then the first in the "
             "map's `zones`. null when the map has no zones or none holds an inlier.")


class HintIn(WireModel):
    """Optional coarse hint of where the camera is: a position with a large uncertainty (a GPS /
    Wi-Fi / beacon fix, the app's last known position) or the objects of a zone (a room, a
    floor). It weights the search of a large map and settles a tie between places in its
    favour; it never makes an answer win that the detections do not support."""

    position: list[float] | None = Field(
        default=None, min_length=3, max_length=3,
        description="The camera's position in the map's world frame, metres.")
    sigma_m: float | None = Field(default=None, gt=0, le=1e4,
                                  description="1-sigma uncertainty of `position` (m).")
    object_ids: list[str] | None = Field(
        default=None, min_length=1, max_length=10_000,
        description="The objects of the zone the camera is in (ids of the map's objects).")
    zone_id: str | None = Field(
        default=None, min_length=1, max_length=128,
        description="The zone the camera is in (a `zone_id` of the map's `zones`): stands for "
                    "that zone's objects.")

    @model_validator(mode="after")
    def _one_kind(self) -> HintIn:
        if sum(x is not None for x in (self.position, self.object_ids, self.zone_id)) != 1:
            raise ValueError("give one of 'position' (with 'sigma_m'), 'object_ids' or "
                             "'zone_id'")
        if self.position is not None:
            if self.sigma_m is None:
                raise ValueError("'sigma_m' is required with 'position'")
            if not all(math.isfinite(x) and abs(x) <= 1e6 for x in self.position):
                raise ValueError("'position' entries must be finite and within +-1e6")
        return self


class LocalizeOptionsIn(WireModel):
    """Solver options; omitted fields take the server defaults (shown)."""

    # `robust_scale` (a number) requires `robust` (a kernel): said in the schema as well.
    model_config = ConfigDict(json_schema_extra={
        "if": {"required": ["robust_scale"],
               "properties": {"robust_scale": {"type": "number"}}},
        "then": {"required": ["robust"],
                 "properties": {"robust": {"type": "string"}}}})

    metric: Literal[(*METRICS, NO_REFINEMENT)] = Field(  # type: ignore[valid-type]
        default="level_set",
        description="Refinement metric (one of the nine), or 'none': the P3P/P2E pose "
                    "unrefined (no covariance).")
    ransac_max_hypotheses: Int = Field(default=300, ge=1, le=100_000,
                                       description="RANSAC budget of minimal samples.")
    inlier_iou: float = Field(default=0.2, gt=0, le=1,
                              description="IoU threshold for a detection to be an inlier.")
    min_inliers: Int = Field(default=2, ge=2, le=MAX_DETECTIONS)
    use_sigma: bool = Field(
        default=True, description="Weight costs by 1/sigma (paper eq. 8) when every detection "
                                  "has a sigma (else every weight is 1; docs/api.md).")
    robust: Literal[ROBUST_KERNELS] | None = Field(  # type: ignore[valid-type]
        default=None, description="Robust kernel of the refinement.")
    robust_scale: float | None = Field(default=None, gt=0, le=1e6,
                                       description="Kernel scale (needs `robust`).")
    unknown_label_policy: Literal[UNKNOWN_LABEL_POLICIES] = "ignore"  # type: ignore[valid-type]
    seed: Annotated[int, Field(ge=0, le=2**32 - 1), BeforeValidator(integral)] | None = 0
    time_budget_ms: float | None = Field(
        default=None, gt=0, le=60_000,
        description="Solve budget (ms); capped by the server's QUADLOC_SOLVE_TIME_BUDGET_MS.")
    max_iterations: Int = Field(default=50, ge=1, le=100,
                                description="Levenberg-Marquardt iteration cap.")
    output_convention: Convention = Field(
        default="opencv", description="Camera axes of the returned pose and covariance.")
    on_ambiguity: Literal[AMBIGUITY_POLICIES] = Field(  # type: ignore[valid-type]
        default="not_localized",
        description="When a distinct pose explains the detections comparably well: "
                    "'not_localized' (reason 'ambiguous') or 'best' (the best pose, localized); "
                    "both list the candidates in `alternatives` with their probabilities.")
    min_confidence: float | None = Field(
        default=None, ge=0, le=1,
        description="Answers with a lower confidence are returned as not localized (reason "
                    "'low_confidence'); null = the calibrated default (docs/api.md).")

    @model_validator(mode="after")
    def _scale_needs_kernel(self) -> LocalizeOptionsIn:
        check_robust(self.robust, self.robust_scale)  # the rule of every layer
        return self


class LocalizeRequest(WireModel):
    """One frame to localize against the map."""

    camera: CameraIn
    detections: list[DetectionIn] = Field(max_length=MAX_DETECTIONS)
    prior: PosePriorIn | None = None
    gravity: GravityIn | None = None
    hint: HintIn | None = None
    frame_id: Text | None = Field(default=None, max_length=256, description="Echoed back.")
    timestamp: float | None = Field(default=None, description="Echoed back (client clock, s).")
    options: LocalizeOptionsIn = Field(default_factory=LocalizeOptionsIn)


class BatchLocalizeRequest(WireModel):
    """Several frames (bounded count) localized in order with the same map version."""

    frames: list[LocalizeRequest] = Field(min_length=1, max_length=MAX_BATCH_FRAMES)


class PoseOut(BaseModel):
    """The camera's pose in the map frame (``world_from_camera``)."""

    quaternion_wxyz: list[float] = Field(description="Unit quaternion (w, x, y, z), w >= 0.")
    quaternion_xyzw: list[float] = Field(
        description="The same quaternion scalar LAST (x, y, z, w): the order of "
                                  "ARKit/simd, ARCore, Unity and ROS.")
    translation_m: list[float] = Field(description="Camera centre in the map frame (m).")
    matrix: list[list[float]] = Field(
        description="4x4 homogeneous world_from_camera, ROW-major: a list of 4 rows, "
                    "`matrix[r][c]`.")
    matrix_column_major: list[float] = Field(
        description="The same 4x4 as 16 numbers in COLUMN-major order (column 0 "
                                  "top to bottom, then column 1...): simd_float4x4(columns:), "
                                  "Unity Matrix4x4, OpenGL/glm, three.js Matrix4.fromArray.")
    convention: Convention = Field(description="Camera axes of this pose.")


class CovarianceOut(BaseModel):
    order: list[str] = Field(default=list(COVARIANCE_ORDER),
                             description="Row/column order of `matrix`.")
    frame: str = Field(default=COVARIANCE_FRAME)
    matrix: list[list[float]]


class InlierOut(BaseModel):
    detection_index: int
    object_id: str
    iou: float
    cost: float


class AlternativeOut(BaseModel):
    """A distinct candidate pose of a verified answer that is not localized (ambiguous, low
    confidence, gravity mismatch) or of an ambiguous one answered with on_ambiguity 'best'."""

    world_from_camera: PoseOut
    confidence: float = Field(ge=0, le=1, description="P(within 10 cm and 5 deg).")
    n_inliers: int
    score: float = Field(description="Sum of the inliers' IoUs.")
    zone: str | None = Field(default=None, description=ZONE_RULE)


class LocalizeResponse(BaseModel):
    """`localized: false` with a `reason` is a normal answer (HTTP 200), not an error."""

    localized: bool
    reason: str | None = Field(
        description="Why not localized: too_few_detections, no_label_match, "
                    "no_hypothesis_above_inlier_threshold, refinement_diverged, "
                    "time_budget_exceeded, ambiguous, low_confidence, gravity_mismatch, "
                    "numerical_failure; null when localized.")
    world_from_camera: PoseOut | None
    covariance: CovarianceOut | None
    confidence: float = Field(
        ge=0, le=1, description="Probability that the pose is within 0.10 m and 5 deg of the "
                                "truth (calibrated on simulated frames, docs/api.md).")
    inliers: list[InlierOut]
    metric: str
    hypotheses_evaluated: int
    used_prior: bool
    refinement_status: str | None = Field(
        default=None,
        description="Status of the last pose refinement: converged, max_iterations, "
                    "time_budget (the solve budget cut it short: the pose is less refined), "
                    "diverged, invalid_projection; null when no refinement ran.")
    pose_source: Literal[POSE_SOURCES] | None = Field(  # type: ignore[valid-type]
        default=None, description="Which path won: 'prior' (the refined client prior) or "
                                  "'ransac'; null when not localized.")
    zone: str | None = Field(
        default=None,
        description=ZONE_RULE + " Set whenever the answer has a pose or its best candidate "
                                "(localized, or not localized with `alternatives`).")
    alternatives: list[AlternativeOut] = Field(
        default_factory=list,
        description="Verified but not localized (ambiguous, low_confidence, gravity_mismatch), "
                    "or localized with "
                    "on_ambiguity 'best' on an ambiguous frame: the distinct candidate poses, "
                    "most probable first, each with its probability (`confidence`).")
    map_id: str
    map_version: int
    timings_ms: dict[str, float]
    frame_id: str | None = None
    timestamp: float | None = None


class BatchLocalizeResponse(BaseModel):
    map_id: str
    map_version: int
    results: list[LocalizeResponse]
