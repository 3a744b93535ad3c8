"""Typed request/response models of the QuadLoc HTTP API (pydantic v2; no server imports).

They mirror the server's wire format (``docs/openapi.json``):

* Pixels with origin at the top-left pixel corner, +x right, +y down. Ellipses are
  ``{cx, cy, a, b, angle}``: centre px, **semi**-axes px (``a`` along ``angle``), ``angle`` in
  **radians** from +x towards +y. A :class:`Box` ``{xmin, ymin, xmax, ymax}`` is turned into its
  inscribed axis-aligned ellipse by the server.
* ``sigma`` is the detector's predicted uncertainty (> 0, cost weight ``1/sigma``);
  ``log_variance`` is ``alpha = log sigma^2`` (``sigma = exp(alpha / 2)``). At most one.
* Poses are ``world_from_camera`` (the camera's pose in the map frame, metres) as a unit
  ``quaternion_wxyz`` (scalar first, ``w >= 0``) + ``translation_m`` and a 4x4 ``matrix``, with
  camera axes ``opencv`` (+X right, +Y down, +Z forward) or ``opengl`` (ARKit/ARCore: +Y up,
  -Z forward) as asked by ``LocalizeOptions.output_convention``.
* Covariances are 6x6 in GTSAM Pose3 tangent order ``[omega_x, omega_y, omega_z, v_x, v_y,
  v_z]`` (radians, metres), right perturbation ``T exp(xi)``, in the camera (body) frame.

Request models reject unknown fields and non-finite numbers *before* anything is sent (so a
typo such as ``sigm=`` fails at once, naming the field). Response models accept fields added by
newer servers. Numpy scalars and arrays are accepted where floats / lists are expected, but numpy
is not needed: this module imports only pydantic (``as_matrix`` / ``as_array`` import numpy on
use).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    model_validator,
)

__all__ = [
    "METRICS",
    "NO_REFINEMENT",
    "ROBUST_KERNELS",
    "Alternative",
    "BatchLocalizeResponse",
    "Box",
    "Calibration",
    "CalibrationQuality",
    "Camera",
    "Covariance",
    "Detection",
    "Ellipse",
    "Gravity",
    "Inlier",
    "LocalizeOptions",
    "LocalizeRequest",
    "LocalizeResponse",
    "MapRecord",
    "MapSummary",
    "MapVersion",
    "PlaceCandidate",
    "Pose",
    "PoseInput",
    "PosePrior",
    "SessionFrame",
    "SessionFrameResult",
    "SessionInfo",
    "SessionOptions",
]

Metric = Literal[
    "iou", "giou", "bbox", "qbbox", "algebraic", "frobenius", "wasserstein", "bhattacharyya",
    "level_set",
]
RobustKernel = Literal["huber", "cauchy", "geman_mcclure"]
#: The nine refinement metrics the server accepts as ``LocalizeOptions.metric`` (the values of
#: :data:`Metric`, spelled once).
METRICS: tuple[str, ...] = get_args(Metric)
#: Robust kernels accepted as ``LocalizeOptions.robust`` (the values of :data:`RobustKernel`).
ROBUST_KERNELS: tuple[str, ...] = get_args(RobustKernel)
Convention = Literal["opencv", "opengl"]
#: ``LocalizeOptions.metric`` value for the unrefined P3P/P2E pose (no covariance).
NO_REFINEMENT = "none"


def _plain(value: Any) -> Any:
    """numpy scalars/arrays -> Python floats/lists (so ``np.float32`` and ``T[:3, 3]`` work),
    recognised without importing numpy."""
    if type(value).__module__ == "numpy":
        if hasattr(value, "tolist") and getattr(value, "ndim", 0) > 0:
            return value.tolist()
        if hasattr(value, "item"):
            return value.item()
    return value


Float = Annotated[float, BeforeValidator(_plain)]
FloatList = Annotated[list[Float], BeforeValidator(_plain)]
Matrix = Annotated[list[FloatList], BeforeValidator(_plain)]

_REQUEST = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)
_RESPONSE = ConfigDict(extra="allow", frozen=True)


# ----------------------------------------------------------------------------------- requests


class Ellipse(BaseModel):
    """Image ellipse: centre ``(cx, cy)`` px (origin top-left pixel corner, +y down), SEMI-axes
    ``a`` (along ``angle``) and ``b`` px, ``angle`` radians from +x towards +y."""

    model_config = _REQUEST
    cx: Float
    cy: Float
    a: Float = Field(gt=0)
    b: Float = Field(gt=0)
    angle: Float = 0.0


class Box(BaseModel):
    """Axis-aligned detection box in px (origin top-left pixel corner)."""

    model_config = _REQUEST
    xmin: Float
    ymin: Float
    xmax: Float
    ymax: Float

    @model_validator(mode="after")
    def _ordered(self) -> Box:
        if not self.xmax > self.xmin:
            raise ValueError(f"xmax ({self.xmax}) must be > xmin ({self.xmin})")
        if not self.ymax > self.ymin:
            raise ValueError(f"ymax ({self.ymax}) must be > ymin ({self.ymin})")
        return self


class Detection(BaseModel):
    """One detected object: exactly one of ``ellipse`` / ``box``, its category ``label``, and
    optionally ``sigma`` or ``log_variance`` (not both) and the detector ``score`` in [0, 1]."""

    model_config = _REQUEST
    label: str = Field(min_length=1)
    ellipse: Ellipse | None = None
    box: Box | None = None
    sigma: Float | None = Field(default=None, gt=0)
    log_variance: Float | None = None
    score: Float | None = Field(default=None, ge=0, le=1)

    @model_validator(mode="after")
    def _one_shape(self) -> Detection:
        if (self.ellipse is None) == (self.box is None):
            raise ValueError("give exactly one of 'ellipse' or 'box'")
        if self.sigma is not None and self.log_variance is not None:
            raise ValueError("give at most one of 'sigma' or 'log_variance'")
        return self


class Camera(BaseModel):
    """Pinhole intrinsics ``fx, fy, cx, cy`` (px, zero skew, undistorted detections) and the
    image size ``width, height`` (px) of the image the detections come from."""

    model_config = _REQUEST
    fx: Float = Field(gt=0)
    fy: Float = Field(gt=0)
    cx: Float
    cy: Float
    width: int = Field(ge=1)
    height: int = Field(ge=1)

    @classmethod
    def from_matrix(cls, K: Any, width: int, height: int) -> Camera:
        """From a 3x3 intrinsic matrix ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        import numpy as np

        K = np.asarray(K, dtype=float)
        if K.shape != (3, 3):
            raise ValueError(f"K: expected shape (3, 3), got {K.shape}")
        return cls(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=width, height=height)


class PoseInput(BaseModel):
    """A ``world_from_camera`` pose sent to the server: a 4x4 ``matrix`` (a list of ROWS,
    row-major) OR ``quaternion_wxyz`` (scalar first) or ``quaternion_xyzw`` (scalar last) +
    ``translation_m`` (metres)."""

    model_config = _REQUEST
    quaternion_wxyz: FloatList | None = Field(default=None, min_length=4, max_length=4)
    quaternion_xyzw: FloatList | None = Field(default=None, min_length=4, max_length=4)
    translation_m: FloatList | None = Field(default=None, min_length=3, max_length=3)
    matrix: Matrix | None = Field(default=None, min_length=4, max_length=4)

    @model_validator(mode="after")
    def _one_form(self) -> PoseInput:
        if self.quaternion_wxyz is not None and self.quaternion_xyzw is not None:
            raise ValueError("give one of 'quaternion_wxyz' or 'quaternion_xyzw'")
        q = self.quaternion_wxyz if self.quaternion_wxyz is not None else self.quaternion_xyzw
        has_q = q is not None or self.translation_m is not None
        if has_q == (self.matrix is not None):
            raise ValueError("give either 'quaternion_wxyz' + 'translation_m' or 'matrix'")
        if has_q and (q is None or self.translation_m is None):
            raise ValueError("'quaternion_wxyz' (or 'quaternion_xyzw') and 'translation_m' go "
                             "together")
        if self.matrix is not None and any(len(row) != 4 for row in self.matrix):
            raise ValueError("'matrix' must be 4x4")
        return self


class PosePrior(BaseModel):
    """An optional prior ``world_from_camera`` with an optional 6x6 ``covariance`` ([omega, v],
    body frame), in the camera axes ``convention`` (e.g. the AR session's tracking pose).
    Build it from a 4x4 array with :meth:`from_matrix`."""

    model_config = _REQUEST
    world_from_camera: PoseInput
    covariance: Matrix | None = None
    convention: Convention = "opencv"

    @classmethod
    def from_matrix(
        cls,
        world_from_camera: Any,
        covariance: Any | None = None,
        convention: Convention = "opencv",
    ) -> PosePrior:
        """From a 4x4 ``world_from_camera`` array (row-major, numpy or nested lists) and an
        optional 6x6 covariance."""
        import numpy as np

        T = np.asarray(world_from_camera, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("world_from_camera: expected a finite 4x4 matrix")
        cov: list[list[float]] | None = None
        if covariance is not None:
            array = np.asarray(covariance, dtype=float)
            if array.shape != (6, 6) or not np.all(np.isfinite(array)):
                raise ValueError("covariance: expected a finite 6x6 matrix")
            cov = array.tolist()
        return cls(world_from_camera=PoseInput(matrix=T.tolist()), covariance=cov,
                   convention=convention)


class Gravity(BaseModel):
    """The gravity direction the device measures (e.g. ARKit/ARCore/CoreMotion gravity): the
    direction gravity pulls (DOWN) in the camera axes ``convention``, any positive length, with
    its angular uncertainty ``sigma_deg`` (1 sigma per tilt axis, default 2). The server
    refines the pose's tilt with it and drops candidates that disagree; an answer whose tilt
    disagrees comes back ``localized: false``, reason ``gravity_mismatch``. An accelerometer at
    rest measures the opposite (up): negate it."""

    model_config = _REQUEST
    direction: FloatList = Field(min_length=3, max_length=3)
    sigma_deg: Float | None = Field(default=None, gt=0, le=30)
    convention: Convention = "opencv"

    @model_validator(mode="after")
    def _nonzero(self) -> Gravity:
        if sum(x * x for x in self.direction) <= 1e-18:
            raise ValueError("direction: must not be the zero vector")
        return self


class Hint(BaseModel):
    """A coarse hint of where the camera is, for maps of many similar rooms: a ``position``
    (map world frame, m) with its 1-sigma ``sigma_m`` (a GPS / Wi-Fi / beacon fix, the app's
    last known position), the ``object_ids`` of the zone the camera is in, or that zone's
    ``zone_id`` (one of the map's ``zones``). The server uses it to settle a tie between places,
    never against the detections (docs/api.md, "Hints")."""

    model_config = _REQUEST
    position: FloatList | None = Field(default=None, min_length=3, max_length=3)
    sigma_m: Float | None = Field(default=None, gt=0, le=1e4)
    object_ids: list[str] | None = Field(default=None, min_length=1)
    zone_id: str | None = Field(default=None, min_length=1, max_length=128)

    @model_validator(mode="after")
    def _one_kind(self) -> Hint:
        if sum(x is not None for x in (self.position, self.object_ids, self.zone_id)) != 1:
            raise ValueError("give one of 'position' (with 'sigma_m'), 'object_ids' or "
                             "'zone_id'")
        if self.position is not None and self.sigma_m is None:
            raise ValueError("sigma_m: required with 'position'")
        return self


class LocalizeOptions(BaseModel):
    """Solver options. ``None`` fields are not sent: the server's defaults apply (level-set
    metric, RANSAC budget 300, inlier IoU 0.2, sigma weighting on, no robust kernel, OpenCV
    output axes -- see docs/api.md)."""

    model_config = _REQUEST
    metric: Metric | Literal["none"] | None = None
    ransac_max_hypotheses: int | None = Field(default=None, ge=1)
    inlier_iou: Float | None = Field(default=None, gt=0, le=1)
    min_inliers: int | None = Field(default=None, ge=2)
    use_sigma: bool | None = None
    robust: RobustKernel | None = None
    robust_scale: Float | None = Field(default=None, gt=0)
    unknown_label_policy: Literal["ignore", "error"] | None = None
    seed: int | None = Field(default=None, ge=0)
    time_budget_ms: Float | None = Field(default=None, gt=0)
    max_iterations: int | None = Field(default=None, ge=1)
    output_convention: Convention | None = None
    on_ambiguity: Literal["not_localized", "best"] | None = None
    min_confidence: Float | None = Field(default=None, ge=0, le=1)


class LocalizeRequest(BaseModel):
    """One frame: intrinsics, detections, optional prior, echoed ``frame_id``/``timestamp``."""

    model_config = _REQUEST
    camera: Camera
    detections: list[Detection]
    prior: PosePrior | None = None
    gravity: Gravity | None = None
    hint: Hint | None = None
    frame_id: str | None = None
    timestamp: Float | None = None
    options: LocalizeOptions = Field(default_factory=LocalizeOptions)

    def to_wire(self) -> dict[str, Any]:
        """JSON body for the server (unset optional fields omitted)."""
        return self.model_dump(mode="json", exclude_none=True)


class SessionOptions(BaseModel):
    """Options of a tracking session (docs/tracking.md). ``None`` fields are not sent: the
    server's defaults apply (a window of 30 frames, the ``isam2`` smoother, inlier IoU 0.2, the
    odometry drift model of docs/tracking.md)."""

    model_config = _REQUEST
    window_frames: int | None = Field(default=None, ge=2, le=300)
    smoother: Literal["isam2", "batch"] | None = None
    inlier_iou: Float | None = Field(default=None, gt=0, le=1)
    odometry_translation_m_per_sqrt_m: Float | None = Field(default=None, ge=0, le=10)
    odometry_translation_m_per_sqrt_s: Float | None = Field(default=None, ge=0, le=10)
    odometry_rotation_deg_per_sqrt_m: Float | None = Field(default=None, ge=0, le=90)
    odometry_rotation_deg_per_sqrt_s: Float | None = Field(default=None, ge=0, le=90)


class SessionFrame(BaseModel):
    """One frame of a tracking session: the detections (as for localize), the camera's pose in
    the app's odometry frame ``odom_from_camera`` (in the session's convention), the client
    clock ``timestamp`` (s, non-decreasing), and optionally a ``prior`` and ``gravity``."""

    model_config = _REQUEST
    detections: list[Detection] = Field(default_factory=list)
    odom_from_camera: PoseInput
    timestamp: Float
    frame_id: str | None = None
    prior: PosePrior | None = None
    gravity: Gravity | None = None

    def to_wire(self) -> dict[str, Any]:
        """JSON body for the server (unset optional fields omitted). A ``gravity`` whose
        ``convention`` was not given is sent without one: the server then reads it in the
        session's convention (docs/tracking.md), not in the model's default ``opencv``."""
        wire = self.model_dump(mode="json", exclude_none=True)
        if self.gravity is not None and "convention" not in self.gravity.model_fields_set:
            del wire["gravity"]["convention"]
        return wire


# ----------------------------------------------------------------------------------- responses


class Pose(BaseModel):
    """``world_from_camera``: the camera's pose in the map frame, with the camera axes
    ``convention``. ``matrix`` is ROW-major (a list of rows, ``matrix[r][c]``);
    ``matrix_column_major`` the same 16 numbers column by column (simd, Unity, OpenGL);
    ``quaternion_xyzw`` the quaternion scalar last. :meth:`as_matrix` gives the 4x4 numpy array;
    for Unity see :func:`quadloc_sdk.geometry.unity_pose_from_world_from_camera`."""

    model_config = _RESPONSE
    quaternion_wxyz: list[float]
    quaternion_xyzw: list[float] | None = None
    translation_m: list[float]
    matrix: list[list[float]]
    matrix_column_major: list[float] | None = None
    convention: Convention = "opencv"

    @model_validator(mode="after")
    def _derived_layouts(self) -> Pose:
        # Older servers send only quaternion_wxyz and matrix: derive the other layouts.
        if self.quaternion_xyzw is None and len(self.quaternion_wxyz) == 4:
            w, x, y, z = self.quaternion_wxyz
            object.__setattr__(self, "quaternion_xyzw", [x, y, z, w])
        if self.matrix_column_major is None and len(self.matrix) == 4:
            object.__setattr__(self, "matrix_column_major",
                               [self.matrix[r][c] for c in range(4) for r in range(4)])
        return self

    def as_matrix(self) -> Any:
        """4x4 ``world_from_camera`` as a float64 numpy array (needs numpy)."""
        import numpy as np

        return np.asarray(self.matrix, dtype=float)


class Covariance(BaseModel):
    """6x6 pose covariance; ``order`` names the rows/columns, ``frame`` states the convention."""

    model_config = _RESPONSE
    order: list[str]
    frame: str = ""
    matrix: list[list[float]]

    def as_array(self) -> Any:
        """6x6 float64 numpy array (needs numpy)."""
        import numpy as np

        return np.asarray(self.matrix, dtype=float)


class Inlier(BaseModel):
    """A detection matched to a map object (``iou`` of detection vs projection, metric ``cost``)."""

    model_config = _RESPONSE
    detection_index: int
    object_id: str
    iou: float
    cost: float


class Alternative(BaseModel):
    """A distinct candidate pose of a verified answer that is not localized (ambiguous, low
    confidence, gravity mismatch) or of an ambiguous one answered with ``on_ambiguity="best"``;
    ``confidence``: its probability of being within 10 cm and 5 deg."""

    model_config = _RESPONSE
    world_from_camera: Pose
    confidence: float
    n_inliers: int
    score: float
    zone: str | None = None  # the map zone of this candidate (docs/api.md, "Zones")


class LocalizeResponse(BaseModel):
    """Answer for one frame. ``localized: false`` with a ``reason`` is a normal answer.
    ``confidence`` is the probability that the pose is within 10 cm and 5 deg."""

    model_config = _RESPONSE
    localized: bool
    reason: str | None = None
    world_from_camera: Pose | None = None
    covariance: Covariance | None = None
    confidence: float = 0.0
    inliers: list[Inlier] = Field(default_factory=list)
    metric: str | None = None
    hypotheses_evaluated: int | None = None
    used_prior: bool | None = None
    refinement_status: str | None = None
    pose_source: str | None = None
    zone: str | None = None  # the map zone of the answer (docs/api.md, "Zones")
    alternatives: list[Alternative] = Field(default_factory=list)
    map_id: str
    map_version: int
    timings_ms: dict[str, float] = Field(default_factory=dict)
    frame_id: str | None = None
    timestamp: float | None = None


class BatchLocalizeResponse(BaseModel):
    model_config = _RESPONSE
    map_id: str
    map_version: int
    results: list[LocalizeResponse]


class MapSummary(BaseModel):
    """One entry of the map list: latest ``version`` and its ``content_hash`` (the ETag)."""

    model_config = _RESPONSE
    map_id: str
    name: str
    version: int
    content_hash: str
    updated_at: str | None = None


class MapVersion(BaseModel):
    """One stored version of a map (``GET /v1/maps/{id}/versions``)."""

    model_config = _RESPONSE
    version: int
    content_hash: str
    created_at: str | None = None


class MapRecord(BaseModel):
    """A stored map version: ``map`` is the document (docs/maps.md format); ``etag`` is the
    response's ``ETag`` header (pass it back as ``if_match`` to update)."""

    model_config = _RESPONSE
    map_id: str
    version: int
    content_hash: str
    created_at: str | None = None
    map: dict[str, Any]
    etag: str | None = None


class CalibrationQuality(BaseModel):
    """How well covariance and confidence describe the errors on a calibration's held-out
    frames: mean NEES of the localized answers within 10 cm (6 = well scaled) and the expected
    calibration error of ``confidence`` (10 equal-width bins) against success = within 10 cm
    and 5 deg of the reference; ``calibration_error_floor``: what a perfectly calibrated
    confidence would show on these frames by sampling alone; ``calibration_error_sd``: the
    error's sampling standard deviation (blocks of consecutive frames)."""

    model_config = _RESPONSE
    frames: int
    localized: int
    nees_frames: int
    mean_nees: float | None = None
    calibration_error: float | None = None
    calibration_error_floor: float | None = None
    calibration_error_sd: float | None = None
    mean_confidence: float | None = None
    success_rate: float | None = None


class Calibration(BaseModel):
    """A map version's own calibration (``POST`` / ``GET /v1/maps/{map_id}/calibration``):
    the fitted covariance scale ``k`` and residual floor of calibration key ``key``, the
    default ``min_confidence``, and the quality ``before`` (shipped constants) / ``after``
    (cross-fitted) on the recording's held-out frames."""

    model_config = _RESPONSE
    map_id: str
    map_version: int
    key: str
    fit_frames: int
    covariance_scale: float
    shipped_covariance_scale: float
    s2_floor: float
    min_confidence: float
    before: CalibrationQuality
    after: CalibrationQuality


class SessionInfo(BaseModel):
    """A tracking session as the server describes it (``POST /v1/maps/{id}/sessions``,
    ``GET /v1/sessions/{id}``): ``state`` is ``initializing``, ``tracking`` or ``lost``,
    ``frames`` the frames received so far."""

    model_config = _RESPONSE
    session_id: str
    url: str
    map_id: str
    map_version: int
    convention: Convention
    state: str
    frames: int
    idle_timeout_s: float


class PlaceCandidate(BaseModel):
    """A place a session's walk may be in (docs/tracking.md, "Places"): this frame's camera
    pose if the walk is there, its posterior ``probability``, and its map ``zone``."""

    model_config = _RESPONSE
    world_from_camera: Pose
    probability: float
    zone: str | None = None


class SessionFrameResult(BaseModel):
    """The answer for one session frame. ``world_from_camera`` / ``covariance`` only while
    ``state == "tracking"``; ``world_from_odom`` aligns the app's odometry frame to the map
    (apply it once to the app's scene); ``confidence`` is P(pose within 10 cm and 5 deg)."""

    model_config = _RESPONSE
    frame_index: int
    frame_id: str | None = None
    timestamp: float
    state: str
    reason: str | None = None
    world_from_camera: Pose | None = None
    covariance: Covariance | None = None
    world_from_odom: Pose | None = None
    world_from_odom_covariance: Covariance | None = None
    confidence: float = 0.0
    inliers: list[Inlier] = Field(default_factory=list)
    zone: str | None = None  # the map zone of the pose (docs/api.md, "Zones")
    #: the places the walk may be in, most probable first (several while ``ambiguous``)
    candidates: list[PlaceCandidate] = Field(default_factory=list)
    n_usable_detections: int = 0
    timings_ms: dict[str, float] = Field(default_factory=dict)
